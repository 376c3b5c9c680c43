"""Blender (Cycles, CPU) side of bench/subsurface.sh: a UV sphere of radius 1 with a Principled BSDF that is all
random-walk subsurface (Subsurface 1, method RANDOM_WALK) under a uniform grey world, seen by a camera on +z. Renders
at 1 sample and at SPP samples and prints the difference of the two times, as bench/cycles_render.py does.
Usage: blender -b --factory-startup --python cycles_subsurface.py -- OUT.exr SIZE SPP BOUNCES THREADS COLOR RADIUS
       IOR ROUGHNESS"""
import sys, time
import bpy

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
scene.render.engine = "CYCLES"
c = scene.cycles
c.device = "CPU"
c.use_denoising = False
c.use_adaptive_sampling = False
c.max_bounces = c.diffuse_bounces = c.glossy_bounces = c.transmission_bounces = bounces
c.caustics_reflective = c.caustics_refractive = True
c.sample_clamp_direct = c.sample_clamp_indirect = 0
c.pixel_filter_type = "BOX"
c.filter_width = 1.0
scene.render.threads_mode = "FIXED"
scene.render.threads = threads
scene.render.resolution_x = scene.render.resolution_y = size
scene.render.resolution_percentage = 100
scene.render.use_persistent_data = False
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
