// tessera-bench: renders fixed scenes at fixed settings and prints the figures a render service is chosen by:
// load and BVH time, time to the first preview, samples and rays per second (by kind), memory per triangle,
// the ray rate of Embree alone on the same kinds of rays, thread scaling, and RMSE against a high-spp reference
// after fixed time budgets with efficiency = 1 / (MSE x seconds).
//
// It also counts heap allocations (operator new, replaced in this program) during renders after the first pass, to
// show that the render loop allocates nothing per sample or per ray: what it reports is per pass, not per sample.
//
//   tessera-bench [--quick] [--scene NAME] [--threads N] [--env-width W] [--json FILE]
//
// --env-width sets the width of glossy_env's sky (its height is half): 512 by default, 4096 for the size of the HDR
// maps scenes are lit with, where light sampling is bound by memory reads.
//
// Run it from the repository root (it reads proto/examples/ and ../shared/scenes/).
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <new>
#include <string>
#include <vector>

#include "renderer/job.h"
#include "renderer/sampling.h"
#include "renderer/scene.h"
#include "renderer/session.h"
#include "renderer/thread_pool.h"

// Counting allocator: every operator new of the program (the render threads' included) bumps one counter.
std::atomic<uint64_t> g_allocations{0};

void* counted_alloc(std::size_t n) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  if (void* p = std::malloc(n ? n : 1)) return p;
  throw std::bad_alloc();
}

void* operator new(std::size_t n) {
  return counted_alloc(n);
}
void* operator new[](std::size_t n) {
  return counted_alloc(n);
}
void operator delete(void* p) noexcept {
  std::free(p);
}
void operator delete[](void* p) noexcept {
  std::free(p);
}
void operator delete(void* p, std::size_t) noexcept {
  std::free(p);
}
void operator delete[](void* p, std::size_t) noexcept {
  std::free(p);
}

namespace {

using namespace tessera;
using nlohmann::json;
using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

size_t current_rss_bytes() {
  std::ifstream statm("/proc/self/statm");
  size_t pages = 0, resident = 0;
  statm >> pages >> resident;
  return resident * static_cast<size_t>(sysconf(_SC_PAGESIZE));
}

size_t peak_rss_bytes() {
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  return static_cast<size_t>(ru.ru_maxrss) * 1024;
}

struct BenchScene {
  std::string name;
  std::string description;
  std::function<std::shared_ptr<Scene>()> make;
  RenderSettings settings;
};

RenderSettings base_settings(int w, int h, int depth) {
  RenderSettings s;
  s.width = w;
  s.height = h;
  s.spp = 16;
  s.seed = 1;
  s.integrator.max_depth = depth;
  return s;
}

std::shared_ptr<Scene> load_job_file(const std::string& path, const json& scene_override = nullptr) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error("cannot open " + path + " (run from the repository root)");
  json job = json::parse(in);
  if (!scene_override.is_null()) job["scene"] = scene_override;
  JobLoadOptions opts;
  opts.scene.asset_root = std::filesystem::path(path).parent_path();
  return load_job(job, opts).scene;
}

std::shared_ptr<Scene> gltf_scene(const std::string& file) {
  if (!std::filesystem::exists(file)) throw std::runtime_error(file + " not found");
  json job = {{"kind", "scene"}, {"scene", {{"gltf", std::filesystem::path(file).filename().string()}}}};
  JobLoadOptions opts;
  opts.scene.asset_root = std::filesystem::path(file).parent_path();
  return load_job(job, opts).scene;
}

// A tessellated sphere of `rings` x `segments` quads as a mesh with smooth normals.
Mesh sphere_mesh(Vec3 c, float r, int rings, int segments, uint32_t material) {
  Mesh m;
  m.material = material;
  for (int i = 0; i <= rings; ++i) {
    float theta = kPi * i / rings;
    for (int j = 0; j <= segments; ++j) {
      float phi = 2 * kPi * j / segments;
      Vec3 n(std::sin(theta) * std::cos(phi), std::cos(theta), std::sin(theta) * std::sin(phi));
      m.positions.push_back(c + n * r);
      m.normals.push_back(n);
    }
  }
  for (int i = 0; i < rings; ++i)
    for (int j = 0; j < segments; ++j) {
      uint32_t a = i * (segments + 1) + j, b = a + segments + 1;
      m.indices.insert(m.indices.end(), {a, b, a + 1, a + 1, b, b + 1});
    }
  return m;
}

// At least a million triangles: a 4 x 4 grid of finely tessellated spheres on a floor under a rectangular light.
std::shared_ptr<Scene> million_scene() {
  auto scene = std::make_shared<Scene>();
  const MaterialRegistry& reg = MaterialRegistry::builtin();
  scene->materials.push_back(reg.create({{"type", "lambert"}, {"albedo", {0.7, 0.6, 0.5}}}, "/", {}));
  scene->materials.push_back(reg.create({{"type", "emission"}, {"radiance", {20, 20, 20}}}, "/", {}));
  scene->material_names = {"diffuse", "light"};
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j)
      scene->meshes.push_back(sphere_mesh(Vec3(i * 2.5f - 3.75f, 1, j * 2.5f - 3.75f), 1, 128, 256, 0));
  Mesh floor;
  floor.positions = {Vec3(-20, 0, -20), Vec3(20, 0, -20), Vec3(20, 0, 20), Vec3(-20, 0, 20)};
  floor.indices = {0, 2, 1, 0, 3, 2};
  scene->meshes.push_back(floor);
  Mesh light;
  light.material = 1;
  light.positions = {Vec3(-2, 8, -2), Vec3(2, 8, -2), Vec3(2, 8, 2), Vec3(-2, 8, 2)};
  light.indices = {0, 1, 2, 0, 2, 3};
  scene->meshes.push_back(light);
  scene->camera.from = Vec3(0, 7, 11);
  scene->camera.to = Vec3(0, 0.5f, 0);
  scene->camera.fov_deg = 45;
  scene->environment.color = Rgb(0.05f);
  scene->finalize();
  return scene;
}

// Glossy objects under a sky with a sun (a w x w/2 map): environment importance sampling and glossy BSDFs.
std::shared_ptr<Scene> glossy_env_scene(int w) {
  const int h = w / 2;
  std::vector<float> rgb(static_cast<size_t>(w) * h * 3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      float v = (y + 0.5f) / h;
      Rgb sky = v < 0.5f ? Rgb(0.3f, 0.5f, 0.9f) * (1.2f - v) : Rgb(0.25f, 0.22f, 0.2f);
      float dx = (x - 0.7f * w) / w, dy = (y - 0.2f * h) / h;
      if (dx * dx + dy * dy < 0.0001f) sky = Rgb(2000, 1800, 1500);
      float* p = &rgb[(static_cast<size_t>(y) * w + x) * 3];
      p[0] = sky.x;
      p[1] = sky.y;
      p[2] = sky.z;
    }
  const MaterialRegistry& reg = MaterialRegistry::builtin();
  auto glossy = [&](json params, json fallback) { return reg.has(params["type"]) ? params : fallback; };
  json scene_doc = {
      {"materials",
       {{"gold", glossy({{"type", "conductor"}, {"metal", "gold"}, {"roughness", 0.2}},
                        {{"type", "lambert"}, {"albedo", {0.8, 0.6, 0.2}}})},
        {"plastic", glossy({{"type", "plastic"}, {"albedo", {0.1, 0.3, 0.8}}, {"roughness", 0.1}},
                           {{"type", "lambert"}, {"albedo", {0.1, 0.3, 0.8}}})},
        {"rough", glossy({{"type", "cook_torrance"}, {"distribution", "ggx"}, {"roughness", 0.4}},
                         {{"type", "lambert"}, {"albedo", 0.7}})},
        {"floor", {{"type", "lambert"}, {"albedo", 0.5}}}}},
      {"objects", json::array({{{"shape", "sphere"}, {"center", {-2.2, 1, 0}}, {"radius", 1}, {"material", "gold"}},
                               {{"shape", "sphere"}, {"center", {0, 1, 0}}, {"radius", 1}, {"material", "plastic"}},
                               {{"shape", "sphere"}, {"center", {2.2, 1, 0}}, {"radius", 1}, {"material", "rough"}},
                               {{"shape", "rectangle"},
                                {"corner", {-10, 0, 10}},
                                {"edge1", {20, 0, 0}},
                                {"edge2", {0, 0, -20}},
                                {"material", "floor"}}})},
      {"camera", {{"from", {0, 2.5, 7}}, {"to", {0, 0.8, 0}}, {"fov_deg", 40}}},
  };
  SceneLoadOptions opts;
  opts.build = false;
  auto scene = load_scene(scene_doc, "/scene", opts);
  scene->environment.map = std::make_shared<EnvironmentMap>(w, h, std::move(rgb));
  scene->environment.color = Rgb(1);
  scene->finalize();
  return scene;
}

struct RayBatch {
  std::vector<Ray> camera, bounce, shadow;
};

// Rays of the three kinds the path tracer casts, made the same way, for tracing with Embree alone.
RayBatch collect_rays(const Scene& scene, const RenderSettings& s) {
  RayBatch batch;
  Camera camera(scene.camera, s.width, s.height);
  for (int y = 0; y < s.height; ++y)
    for (int x = 0; x < s.width; ++x) {
      PixelSampler sampler(s.seed, static_cast<uint32_t>(y * s.width + x), 0);
      Vec2 jitter = sampler.get2d();
      Ray ray = camera.generate_ray(Vec2(x + jitter.x, y + jitter.y), sampler.get2d());
      batch.camera.push_back(ray);
      SurfaceInteraction si;
      if (!scene.intersect(ray, &si)) continue;
      // An incoherent bounce: cosine-distributed about the normal, on the viewer's side.
      Vec3 n = dot(si.sp.ng, ray.dir) < 0 ? si.sp.ng : -si.sp.ng;
      Vec3 d = Frame::from_normal(n).to_world(sample_cosine_hemisphere(sampler.get2d()));
      Ray bounce;
      bounce.origin = offset_ray_origin(si.sp.p, si.sp.ng, d);
      bounce.dir = d;
      batch.bounce.push_back(bounce);
      LightSample ls;
      float u_sel = sampler.get1d();
      if (scene.lights().sample(si.sp.p, u_sel, sampler.get2d(), &ls)) {
        Ray shadow;
        shadow.origin = offset_ray_origin(si.sp.p, si.sp.ng, ls.wi);
        shadow.dir = ls.wi;
        shadow.tmax = std::isinf(ls.dist) ? kInfinity : ls.dist * 0.999f;
        batch.shadow.push_back(shadow);
      }
    }
  return batch;
}

// Rays per second of `count` rays traced by `trace(begin, end)` (which returns how many of rays [begin, end) hit, so
// the work is not optimised away), in chunks on the pool, repeated for at least half a second.
template <typename Trace>
double timed_rate(size_t count, ThreadPool& pool, const Trace& trace) {
  if (count == 0) return 0;
  const size_t chunk = 4096, chunks = (count + chunk - 1) / chunk;
  std::vector<uint64_t> hits(pool.size(), 0);
  auto start = Clock::now();
  int repeats = 0;
  do {
    pool.parallel_for(
        chunks, [&](size_t c, int worker) { hits[worker] += trace(c * chunk, std::min(count, (c + 1) * chunk)); });
    ++repeats;
  } while (seconds_since(start) < 0.5);
  return static_cast<double>(count) * repeats / seconds_since(start);
}

// Rays per second of Embree alone over `rays`, one by one.
double raw_rate(const Scene& scene, const std::vector<Ray>& rays, bool occlusion, ThreadPool& pool) {
  return timed_rate(rays.size(), pool, [&](size_t begin, size_t end) {
    uint64_t h = 0;
    for (size_t i = begin; i < end; ++i) {
      if (occlusion) {
        h += scene.accel().occluded(rays[i]);
      } else {
        RayHit hit;
        h += scene.accel().intersect(rays[i], &hit);
      }
    }
    return h;
  });
}

// Rays per second of Embree alone over `rays` traced in packets of neighbours (rays are in scanline order).
double raw_packet_rate(const Scene& scene, const std::vector<Ray>& rays, ThreadPool& pool) {
  return timed_rate(rays.size(), pool, [&](size_t begin, size_t end) {
    uint64_t h = 0;
    RayHit hit[Accel::kPacketSize];
    bool found[Accel::kPacketSize];
    for (size_t i = begin; i < end; i += Accel::kPacketSize) {
      const int n = static_cast<int>(std::min<size_t>(Accel::kPacketSize, end - i));
      scene.accel().intersect_packet(&rays[i], n, hit, found);
      for (int k = 0; k < n; ++k) h += found[k];
    }
    return h;
  });
}

// Heap allocations after the first pass of a render (the first pass warms up per-thread arenas).
struct AllocationCount {
  uint64_t allocations = 0;
  uint32_t passes = 0;   // passes after the first
  uint64_t samples = 0;  // pixel samples in those passes
  uint64_t rays = 0;     // rays in those passes
};

std::vector<float> render_image(std::shared_ptr<const Scene> scene, RenderSettings s, ThreadPool& pool,
                                RenderProgress* progress = nullptr, double* first_preview_s = nullptr,
                                AllocationCount* allocs = nullptr) {
  RenderSession session(scene, s, pool);
  auto start = Clock::now();
  bool first = true;
  uint64_t allocs_at_first = 0;
  RenderProgress at_first;
  session.run([&](const RenderProgress& p, const Film&) {
    if (first) {
      if (first_preview_s) *first_preview_s = seconds_since(start);
      allocs_at_first = g_allocations.load();
      at_first = p;
    }
    first = false;
  });
  const RenderProgress& end = session.progress();
  if (allocs) {
    allocs->allocations = g_allocations.load() - allocs_at_first;
    allocs->passes = end.pass - at_first.pass;
    allocs->samples = static_cast<uint64_t>(end.samples_done - at_first.samples_done) * static_cast<uint64_t>(s.width) *
                      static_cast<uint64_t>(s.height);
    allocs->rays = end.rays.total() - at_first.rays.total();
  }
  if (progress) *progress = end;
  return session.film().resolve();
}

// The median of `v` (the mean of the middle two for an even count).
double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

double rmse(const std::vector<float>& a, const std::vector<float>& b) {
  double s = 0;
  for (size_t i = 0; i < a.size(); ++i) s += (a[i] - b[i]) * (a[i] - b[i]);
  return std::sqrt(s / a.size());
}

}  // namespace

int main(int argc, char** argv) {
  bool quick = false;
  std::string only, json_path;
  int threads = 0, env_width = 512;
  for (int i = 1; i < argc; ++i) {
    std::string a = argv[i];
    if (a == "--quick")
      quick = true;
    else if (a == "--scene" && i + 1 < argc)
      only = argv[++i];
    else if (a == "--threads" && i + 1 < argc)
      threads = std::atoi(argv[++i]);
    else if (a == "--json" && i + 1 < argc)
      json_path = argv[++i];
    else if (a == "--env-width" && i + 1 < argc && std::atoi(argv[i + 1]) >= 2 && std::atoi(argv[i + 1]) <= 16384)
      env_width = std::atoi(argv[++i]);
    else {
      std::fprintf(stderr,
                   "usage: tessera-bench [--quick] [--scene cornell|helmet|million|glossy_env] [--threads N] "
                   "[--env-width 2..16384] [--json FILE]\n");
      return 2;
    }
  }
  enable_flush_to_zero();
  std::vector<BenchScene> scenes = {
      {"cornell", "Cornell box, 512x512, Lambert, one area light",
       [] { return load_job_file("proto/examples/cornell.json"); }, base_settings(512, 512, 8)},
      {"helmet", "DamagedHelmet.glb (textured glTF), 512x512, white environment",
       [] { return gltf_scene("../shared/scenes/damagedhelmet/DamagedHelmet.glb"); }, base_settings(512, 512, 8)},
      {"million", "16 spheres x 65,536 triangles + floor, area light, 512x512", million_scene,
       base_settings(512, 512, 6)},
      {"glossy_env",
       "glossy spheres under an HDR sky (" + std::to_string(env_width) + "x" + std::to_string(env_width / 2) +
           ") with a sun, 512x512",
       [env_width] { return glossy_env_scene(env_width); }, base_settings(512, 512, 8)},
  };
  const std::vector<double> budgets = quick ? std::vector<double>{0.25, 1, 4} : std::vector<double>{1, 4, 16};
  ThreadPool pool(threads);
  ThreadPool single(1);
  json report = json::array();
  std::printf("tessera-bench: %d threads%s\n", pool.size(), quick ? " (quick)" : "");
  for (BenchScene& bs : scenes) {
    if (!only.empty() && bs.name != only) continue;
    json r = {{"scene", bs.name}};
    std::printf("\n== %s: %s\n", bs.name.c_str(), bs.description.c_str());
    size_t rss_before = current_rss_bytes();
    auto t0 = Clock::now();
    std::shared_ptr<Scene> scene;
    try {
      scene = bs.make();
    } catch (const std::exception& e) {
      std::printf("   skipped: %s\n", e.what());
      continue;
    }
    double load_s = seconds_since(t0);
    size_t rss_after = current_rss_bytes();
    size_t tris = scene->unique_triangle_count();
    r["load_s"] = load_s;
    r["bvh_s"] = scene->build_seconds();
    r["triangles"] = tris;
    r["bytes_per_triangle"] = tris ? double(rss_after - rss_before) / tris : 0.0;
    std::printf("   load %.3f s (BVH and lights %.3f s), %zu triangles, %.0f bytes/triangle (resident growth)\n",
                load_s, scene->build_seconds(), tris, tris ? double(rss_after - rss_before) / tris : 0.0);

    // Throughput at all threads and at one.
    RenderProgress p;
    double first_preview = 0;
    AllocationCount allocs;
    render_image(scene, bs.settings, pool, &p, &first_preview, &allocs);
    // The same render on one thread: the same passes, so per-pass work weighs the same in both.
    RenderProgress p1;
    render_image(scene, bs.settings, single, &p1);
    double efficiency = p1.samples_per_s > 0 ? p.samples_per_s / (p1.samples_per_s * pool.size()) : 0;
    double ray_rate = p.rays.total() / p.elapsed_s;
    std::printf("   first preview %.3f s; %.3g samples/s; %.3g rays/s (camera %.3g, bounce %.3g, shadow %.3g)\n",
                first_preview, p.samples_per_s, ray_rate, p.rays.camera / p.elapsed_s, p.rays.bounce / p.elapsed_s,
                p.rays.shadow / p.elapsed_s);
    std::printf("   1 thread %.3g samples/s; %d threads %.3g samples/s: parallel efficiency %.2f\n", p1.samples_per_s,
                pool.size(), p.samples_per_s, efficiency);
    std::printf(
        "   heap allocations after the first pass: %llu in %u passes (%.3g samples, %.3g rays): %.2g per pass, "
        "%.2g per million rays\n",
        static_cast<unsigned long long>(allocs.allocations), allocs.passes, double(allocs.samples), double(allocs.rays),
        allocs.passes ? double(allocs.allocations) / allocs.passes : 0.0,
        allocs.rays ? 1e6 * double(allocs.allocations) / double(allocs.rays) : 0.0);
    r["heap_allocations"] = {{"allocations", allocs.allocations},
                             {"passes", allocs.passes},
                             {"samples", allocs.samples},
                             {"rays", allocs.rays}};
    r["first_preview_s"] = first_preview;
    r["samples_per_s"] = p.samples_per_s;
    r["rays_per_s"] = ray_rate;
    r["rays"] = {{"camera", p.rays.camera}, {"bounce", p.rays.bounce}, {"shadow", p.rays.shadow}};
    r["samples_per_s_1_thread"] = p1.samples_per_s;
    r["parallel_efficiency"] = efficiency;

    // Embree alone on rays of the same kinds: the time the path tracer's ray mix would take with no shading. The
    // speed of a shared VM drifts by 10 % and more between seconds, so the ratio is measured in interleaved rounds
    // (a render at all threads, then Embree alone on each kind) and reported as the median of the rounds' ratios,
    // with their range; the rates printed are the medians of the rounds.
    RayBatch batch = collect_rays(*scene, bs.settings);
    const int rounds = quick ? 3 : 5;
    std::vector<double> rcs, rbs, rss, rcps, ratios, ratios_packets;
    for (int k = 0; k < rounds; ++k) {
      RenderProgress pk;
      render_image(scene, bs.settings, pool, &pk);
      const double rc = raw_rate(*scene, batch.camera, false, pool), rb = raw_rate(*scene, batch.bounce, false, pool),
                   rs = raw_rate(*scene, batch.shadow, true, pool);
      // The path tracer sends camera rays to Embree in packets of neighbouring pixels; the reference traces every
      // ray alone, as incoherent rays, and is also given with its camera rays in packets (like for like).
      const double rcp = raw_packet_rate(*scene, batch.camera, pool);
      const double rest = (rb > 0 ? pk.rays.bounce / rb : 0) + (rs > 0 ? pk.rays.shadow / rs : 0);
      ratios.push_back(((rc > 0 ? pk.rays.camera / rc : 0) + rest) / pk.elapsed_s);
      ratios_packets.push_back(((rcp > 0 ? pk.rays.camera / rcp : 0) + rest) / pk.elapsed_s);
      rcs.push_back(rc);
      rbs.push_back(rb);
      rss.push_back(rs);
      rcps.push_back(rcp);
    }
    const auto [ratio_lo, ratio_hi] = std::minmax_element(ratios.begin(), ratios.end());
    const double rc = median(rcs), rb = median(rbs), rs = median(rss), rcp = median(rcps);
    const double ratio = median(ratios), ratio_packets = median(ratios_packets);
    std::printf(
        "   Embree alone: camera %.3g (in packets of %d: %.3g), bounce %.3g, shadow %.3g rays/s; path tracer / "
        "Embree-alone rate %.2f (%d rounds %.2f-%.2f; %.2f with camera rays in packets for both)\n",
        rc, Accel::kPacketSize, rcp, rb, rs, ratio, rounds, *ratio_lo, *ratio_hi, ratio_packets);
    r["embree_alone"] = {{"camera", rc},          {"camera_packets", rcp}, {"bounce", rb},
                         {"shadow", rs},          {"ratio", ratio},        {"ratio_camera_packets", ratio_packets},
                         {"ratio_rounds", ratios}};

    // Convergence: RMSE against a high-spp reference after fixed time budgets, at a quarter of the resolution.
    RenderSettings small = bs.settings;
    small.width /= 4;
    small.height /= 4;
    RenderSettings ref = small;
    ref.seed = 999;
    ref.spp = quick ? 1024 : 8192;
    auto tr = Clock::now();
    std::vector<float> reference = render_image(scene, ref, pool);
    std::printf("   reference: %dx%d, %u spp in %.1f s\n", ref.width, ref.height, ref.spp, seconds_since(tr));
    // The sampler at equal samples: Owen-scrambled Sobol against independent numbers, RMSE at 16 spp.
    {
      json sampler_rmse;
      for (SamplerKind kind : {SamplerKind::kSobol, SamplerKind::kIndependent}) {
        RenderSettings b = small;
        b.spp = 16;
        b.sampler = kind;
        double e = rmse(render_image(scene, b, pool), reference);
        sampler_rmse[sampler_name(kind)] = e;
      }
      const double ratio = sampler_rmse["sobol"].get<double>() / sampler_rmse["independent"].get<double>();
      std::printf("   16 spp RMSE: Sobol %.5f, independent %.5f (Sobol / independent %.2f)\n",
                  sampler_rmse["sobol"].get<double>(), sampler_rmse["independent"].get<double>(), ratio);
      sampler_rmse["ratio"] = ratio;
      r["sampler_rmse_16spp"] = sampler_rmse;
    }
    json conv = json::array();
    for (double budget : budgets) {
      RenderSettings b = small;
      b.spp = 1u << 16;
      b.time_limit_s = budget;
      RenderProgress bp;
      std::vector<float> img = render_image(scene, b, pool, &bp);
      double e = rmse(img, reference);
      double eff = 1.0 / (e * e * bp.elapsed_s);
      std::printf("   budget %5.2f s: %5u spp in %.2f s, RMSE %.5f, efficiency 1/(MSE*s) %.4g\n", budget,
                  bp.samples_done, bp.elapsed_s, e, eff);
      conv.push_back({{"budget_s", budget},
                      {"spp", bp.samples_done},
                      {"seconds", bp.elapsed_s},
                      {"rmse", e},
                      {"efficiency", eff}});
    }
    r["convergence"] = conv;
    r["peak_rss_bytes"] = peak_rss_bytes();
    report.push_back(r);
  }
  std::printf("\npeak resident memory %.1f MiB\n", peak_rss_bytes() / 1048576.0);
  if (!json_path.empty()) std::ofstream(json_path) << report.dump(2) << "\n";
  return 0;
}
