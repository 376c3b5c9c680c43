"""What the Blender (Cycles, CPU) sides of the benchmarks share: the render settings that match tessera's (no
denoising, no adaptive sampling, every bounce limit the same, caustics on, no clamping, a 1-pixel box filter, a fixed
number of threads, a 32-bit EXR), and the timing: the scene rendered from scratch at 1 sample and at SPP samples, the
difference printed as the time of SPP - 1 samples scaled to SPP, without import, scene sync, kernel loading and BVH
build (persistent data would keep the first render's sample count in Blender 3.4)."""
import time
import bpy


def configure(scene, width, height, bounces, threads, out, seed=1, threshold=0.0, min_samples=0):
    """threshold > 0 turns Cycles' adaptive sampling on at that noise threshold (Blender's default is 0.01), with
    min_samples (0: Cycles' automatic choice, its default)."""
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
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    scene.render.filepath = out


def time_render(scene, spp, adaptive=False):
    """Uniform sampling: the time of SPP - 1 samples scaled to SPP; adaptive sampling: the render less its setup."""
    c = scene.cycles
    c.samples = 1
    t = time.time()
    bpy.ops.render.render(write_still=False)
    t_one = time.time() - t
    c.samples = spp
    t = time.time()
    bpy.ops.render.render(write_still=True)
    t_all = time.time() - t
    scale = 1.0 if adaptive else spp / max(spp - 1, 1)
    print("CYCLES_RENDER_SECONDS %.3f" % ((t_all - t_one) * scale))
