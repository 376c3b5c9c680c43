"""Blender (Cycles, CPU) side of bench/subsurface.sh: a UV sphere of radius 1 with a Principled BSDF that is all
random-walk subsurface (Subsurface 1, method RANDOM_WALK) under a uniform grey world, seen by a camera on +z. Times
it as bench/cycles_common.py does.
Usage: blender -b --factory-startup --python cycles_subsurface.py -- OUT.exr SIZE SPP BOUNCES THREADS COLOR RADIUS
       IOR ROUGHNESS"""
import os, sys
import bpy

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import cycles_common  # noqa: E402

a = sys.argv[sys.argv.index("--") + 1:]
out, size, spp, bounces, threads = a[0], int(a[1]), int(a[2]), int(a[3]), int(a[4])
color, radius, ior, roughness = float(a[5]), float(a[6]), float(a[7]), float(a[8])
bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene
bpy.ops.mesh.primitive_uv_sphere_add(segments=128, ring_count=64, radius=1, location=(0, 0, 0))
sphere = bpy.context.active_object
bpy.ops.object.shade_smooth()
mat = bpy.data.materials.new("skin")
mat.use_nodes = True
p = mat.node_tree.nodes["Principled BSDF"]
p.subsurface_method = "RANDOM_WALK"
p.inputs["Base Color"].default_value = (color, color, color, 1)
p.inputs["Subsurface"].default_value = 1.0
p.inputs["Subsurface Color"].default_value = (color, color, color, 1)
p.inputs["Subsurface Radius"].default_value = (radius, radius * 0.5, radius * 0.25)
p.inputs["Subsurface IOR"].default_value = ior
p.inputs["IOR"].default_value = ior
p.inputs["Roughness"].default_value = roughness
sphere.data.materials.append(mat)
cam_data = bpy.data.cameras.new("cam")
cam_data.sensor_fit = "VERTICAL"
cam_data.angle = 0.6981317  # 40 degrees
cam = bpy.data.objects.new("cam", cam_data)
cam.location = (0, 0, 3.5)
scene.collection.objects.link(cam)
scene.camera = cam
world = bpy.data.worlds.new("grey")
world.use_nodes = True
world.node_tree.nodes["Background"].inputs[0].default_value = (0.8, 0.8, 0.8, 1)
world.node_tree.nodes["Background"].inputs[1].default_value = 1.0
scene.world = world
cycles_common.configure(scene, size, size, bounces, threads, out)
cycles_common.time_render(scene, spp)
