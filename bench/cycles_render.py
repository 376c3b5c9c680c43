"""Blender (Cycles, CPU) side of bench/cycles_compare.sh: imports a glTF, renders it at the given settings with no
denoising, no adaptive sampling, a 1-pixel box filter and a black world. It renders twice from scratch, at 1 sample
and at SPP samples, and prints the difference of the two times: the time of SPP - 1 samples, without import, scene
sync, kernel loading and BVH build (persistent data would keep the first render's sample count in Blender 3.4).
Usage: blender -b --factory-startup --python cycles_render.py -- SCENE.gltf OUT.exr WIDTH HEIGHT SPP BOUNCES THREADS [SEED]"""
import sys, time
import bpy
import numpy

# Debian 12 ships Blender 3.4, whose glTF importer still uses numpy.bool, with NumPy 1.24, which removed that alias.
if not hasattr(numpy, "bool"):
    numpy.bool = bool

args = sys.argv[sys.argv.index("--") + 1:]
gltf, out, width, height, spp, bounces, threads = args[0], args[1], int(args[2]), int(args[3]), int(args[4]), int(args[5]), int(args[6])
seed = int(args[7]) if len(args) > 7 else 1
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
c.use_adaptive_sampling = False
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
world.node_tree.nodes["Background"].inputs[1].default_value = 0.0
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
print("CYCLES_RENDER_SECONDS %.3f" % ((t_all - t_one) * spp / max(spp - 1, 1)))
