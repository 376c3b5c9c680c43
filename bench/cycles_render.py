"""Blender (Cycles, CPU) side of bench/cycles_compare.sh and bench/cycles_adaptive.sh: imports a glTF, renders it at
the given settings with no denoising, a 1-pixel box filter and a uniform world (black by default). It renders twice
from scratch, at 1 sample and at SPP samples, and prints the difference of the two times (bench/cycles_common.py).
With THRESHOLD > 0, Cycles' adaptive sampling is on at that noise threshold (Blender's default is 0.01) with
MIN_SAMPLES (0: Cycles' automatic choice, its default), SPP the most any pixel gets; the time printed is then that of
the adaptive render less that of the 1-sample one.
Usage: blender -b --factory-startup --python cycles_render.py -- SCENE.gltf OUT.exr WIDTH HEIGHT SPP BOUNCES THREADS
         [SEED [THRESHOLD [MIN_SAMPLES [WORLD]]]]   (WORLD: the world's grey level, 0 by default)"""
import os, sys
import bpy
import numpy

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import cycles_common  # noqa: E402

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
cycles_common.configure(scene, width, height, bounces, threads, out, seed, threshold, min_samples)
world = bpy.data.worlds.new("black")
world.use_nodes = True
world.node_tree.nodes["Background"].inputs[0].default_value = (world_grey, world_grey, world_grey, 1.0)
world.node_tree.nodes["Background"].inputs[1].default_value = 1.0 if world_grey > 0 else 0.0
scene.world = world
cycles_common.time_render(scene, spp, adaptive=threshold > 0)
