"""Blender (Cycles, CPU) side of bench/cycles_compare.sh and bench/cycles_adaptive.sh: imports a glTF, renders it at
the given settings with no denoising, a 1-pixel box filter and a uniform world (black by default). It renders twice
from scratch, at 1 sample and at SPP samples, and prints the difference of the two times: the time of SPP - 1
samples, without import, scene sync, kernel loading and BVH build (persistent data would keep the first render's
sample count in Blender 3.4).
With THRESHOLD > 0, Cycles' adaptive sampling is on at that noise threshold (Blender's default is 0.01) with
MIN_SAMPLES (0: Cycles' automatic choice, its default), SPP the most any pixel gets; the time printed is then that of
the adaptive render less that of the 1-sample one.
Usage: blender -b --factory-startup --python cycles_render.py -- SCENE.gltf OUT.exr WIDTH HEIGHT SPP BOUNCES THREADS
         [SEED [THRESHOLD [MIN_SAMPLES [WORLD]]]]   (WORLD: the world's grey level, 0 by default)"""
import sys, time
import bpy
import numpy

# Debian 12 ships Blender 3.4, whose glTF importer still uses numpy.bool, with NumPy 1.24, which removed that alias.
if not hasattr(numpy, "bool"):
    numpy.bool = bool

args = sys.argv[sys.argv.index("--") + 1:]
gltf, out, width, height, spp, bounces, threads = args[0], args[1], int(args[2]), int(args[3]), int(args[4]), int(args[5]), int(args[6])
seed = int(args[7]) if len(args) > 7 else 1
threshold = float(args[8]) if len(args) > 8 else 0.0
min_samples = int(args[9]) if len(args) > 9 else 0
world_grey = float(args[10]) if len(args) > 10 else 0.0
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.gltf(filepath=gltf)
scene = bpy.context.scene
cams = [o for o in scene.objects if o.type == "CAMERA"]
scene.camera = cams[0]
cams[0].data.sensor_fit = "VERTICAL"
scene.render.engine = "CYCLES"
c = scene.cycles
c.device = "CPU"
c.use_denoising = False
c.use_adaptive_sampling = threshold > 0
c.adaptive_threshold = threshold
c.adaptive_min_samples = min_samples
c.max_bounces = c.diffuse_bounces = c.glossy_bounces = c.transmission_bounces = bounces
c.transparent_max_bounces = bounces
c.caustics_reflective = c.caustics_refractive = True
c.sample_clamp_direct = c.sample_clamp_indirect = 0
c.pixel_filter_type = "BOX"
c.filter_width = 1.0
c.seed = seed
scene.render.threads_mode = "FIXED"
scene.render.threads = threads
scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = width, height, 100
scene.render.use_persistent_data = False
world = bpy.data.worlds.new("black")
world.use_nodes = True
world.node_tree.nodes["Background"].inputs[0].default_value = (world_grey, world_grey, world_grey, 1.0)
world.node_tree.nodes["Background"].inputs[1].default_value = 1.0 if world_grey > 0 else 0.0
scene.world = world
scene.render.image_settings.file_format = "OPEN_EXR"
scene.render.image_settings.color_depth = "32"
scene.render.filepath = out
c.samples = 1
t = time.time()
bpy.ops.render.render(write_still=False)
t_one = time.time() - t
c.samples = spp
t = time.time()
bpy.ops.render.render(write_still=True)
t_all = time.time() - t
# Uniform sampling: the time of SPP - 1 samples scaled to SPP; adaptive sampling: the render less its setup.
scale = 1.0 if threshold > 0 else spp / max(spp - 1, 1)
print("CYCLES_RENDER_SECONDS %.3f" % ((t_all - t_one) * scale))
