#include "renderer/session.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <optional>

#include "renderer/scene.h"

namespace tessera {

const char* stop_reason_name(StopReason r) {
  switch (r) {
    case StopReason::kSamples: return "samples";
    case StopReason::kTimeLimit: return "time_limit";
    case StopReason::kNoiseTarget: return "noise_target";
    case StopReason::kStopped: return "stopped";
    case StopReason::kCancelled: return "cancelled";
  }
  return "samples";
}

RenderSession::RenderSession(std::shared_ptr<const Scene> scene, const RenderSettings& settings, ThreadPool& pool)
    : scene_(std::move(scene)),
      settings_(settings),
      pool_(pool),
      camera_(scene_->camera, settings.width, settings.height),
      film_(settings.width, settings.height) {
  if (settings_.region.width <= 0 || settings_.region.height <= 0) {
    settings_.region = {0, 0, settings.width, settings.height};
  } else {
    // Clip the crop window to the image.
    RenderSettings::Region& r = settings_.region;
    int x1 = std::min(r.x + r.width, settings.width), y1 = std::min(r.y + r.height, settings.height);
    r.x = std::clamp(r.x, 0, settings.width);
    r.y = std::clamp(r.y, 0, settings.height);
    r.width = std::max(0, x1 - r.x);
    r.height = std::max(0, y1 - r.y);
  }
  tiles_x_ = (settings_.region.width + settings.tile_size - 1) / settings.tile_size;
  tiles_y_ = (settings_.region.height + settings.tile_size - 1) / settings.tile_size;
  for (int i = 0; i < pool.size(); ++i) arenas_.push_back(std::make_unique<ScratchArena>());
  counters_.resize(pool.size());
  nonfinite_.resize(pool.size());
  progress_.samples_total = settings.spp;
}

void RenderSession::restore(Film film, uint32_t passes, double elapsed_s) {
  film_ = std::move(film);
  progress_.pass = passes;
  progress_.samples_done = film_.samples();
  progress_.elapsed_s = elapsed_s;
}

void RenderSession::render_tile(size_t tile, int worker, uint32_t first_sample, uint32_t sample_count) {
  const int tx = static_cast<int>(tile % tiles_x_), ty = static_cast<int>(tile / tiles_x_);
  const RenderSettings::Region& region = settings_.region;
  const int x0 = region.x + tx * settings_.tile_size, y0 = region.y + ty * settings_.tile_size;
  const int x1 = std::min(x0 + settings_.tile_size, region.x + region.width);
  const int y1 = std::min(y0 + settings_.tile_size, region.y + region.height);
  ScratchArena& arena = *arenas_[worker];
  // Counted on the stack and added once per tile: the per-worker slots sit side by side, and incrementing them per
  // ray would make the render threads fight over one cache line.
  RayCounters counters;
  uint64_t nonfinite = 0;
  const Scene& scene = *scene_;
  const bool uses_lens = camera_.uses_lens();
  const RayCone cone = camera_.pixel_cone();
  // Camera rays of up to kGroup neighbouring pixels in a row, at the same sample index, go to Embree as one packet:
  // they are coherent, and a packet traces them several times faster than one by one. Each pixel still gets its
  // samples in order, and its paths are those it would trace alone (up to Embree's rounding of sphere hits).
  constexpr int kGroup = Accel::kPacketSize;
  const PixelSampler::SeedKeys seed_keys(settings_.seed);
  PixelSampler samplers[kGroup];
  Ray rays[kGroup];
  RayHit hits[kGroup];
  bool found[kGroup];
  for (int y = y0; y < y1; ++y) {
    for (int gx = x0; gx < x1; gx += kGroup) {
      const int n = std::min(kGroup, x1 - gx);
      const uint32_t first_pixel =
          static_cast<uint32_t>(y) * static_cast<uint32_t>(settings_.width) + static_cast<uint32_t>(gx);
      for (uint32_t s = first_sample; s < first_sample + sample_count; ++s) {
        for (int i = 0; i < n; ++i) {
          PixelSampler& sampler = samplers[i];
          sampler = PixelSampler(seed_keys, first_pixel + static_cast<uint32_t>(i), s, settings_.sampler);
          Vec2 jitter = sampler.get2d();
          Vec2 lens;
          if (uses_lens) lens = sampler.get2d();
          else sampler.skip2d();
          rays[i] = camera_.generate_ray(Vec2(static_cast<float>(gx + i) + jitter.x, static_cast<float>(y) + jitter.y),
                                         lens);
        }
        scene.accel().intersect_packet(rays, n, hits, found);
        for (int i = 0; i < n; ++i) {
          const PrimaryHit primary{found[i], hits[i]};
          Rgb l = trace_path(scene, rays[i], &primary, samplers[i], settings_.integrator, arena, counters, cone);
          if (!is_finite(l) || l.x < 0 || l.y < 0 || l.z < 0) {
            ++nonfinite;
            l = Rgb(0);
          }
          film_.add_sample(gx + i, y, l);
        }
      }
    }
  }
  counters_[worker] += counters;
  nonfinite_[worker] += nonfinite;
}

StopReason RenderSession::run(const std::function<void(const RenderProgress&, const Film&)>& on_pass) {
  using clock = std::chrono::steady_clock;
  const auto start = clock::now();
  const double elapsed_before = progress_.elapsed_s;
  const uint32_t samples_before = progress_.samples_done;
  const size_t tile_count = static_cast<size_t>(tiles_x_) * static_cast<size_t>(tiles_y_);
  const double pixels = static_cast<double>(settings_.region.width) * settings_.region.height;
  auto budget_met = [&]() -> std::optional<StopReason> {
    if (progress_.samples_done >= settings_.spp) return StopReason::kSamples;
    if (settings_.time_limit_s > 0 && progress_.elapsed_s >= settings_.time_limit_s) return StopReason::kTimeLimit;
    if (settings_.noise_target > 0 && progress_.samples_done >= 4 &&
        progress_.relative_error <= settings_.noise_target)
      return StopReason::kNoiseTarget;
    return std::nullopt;
  };
  if (auto r = budget_met()) return *r;
  // Passes start at one sample and grow geometrically, so the first preview comes fast and later passes amortise
  // the per-pass work (previews, checkpoints); a pass is kept near two seconds so previews stay fresh.
  uint32_t pass_samples = 1;
  for (;;) {
    if (cancel_.load()) return StopReason::kCancelled;
    if (stop_.load()) return StopReason::kStopped;
    const uint32_t first = progress_.samples_done;
    const uint32_t count = std::min(pass_samples, settings_.spp - first);
    const auto pass_start = clock::now();
    pool_.parallel_for(tile_count, [&](size_t tile, int worker) {
      if (cancel_.load(std::memory_order_relaxed)) return;
      render_tile(tile, worker, settings_.first_sample + first, count);
    });
    if (cancel_.load()) return StopReason::kCancelled;
    const double pass_s = std::chrono::duration<double>(clock::now() - pass_start).count();
    film_.set_samples(first + count);
    progress_.pass += 1;
    progress_.samples_done = first + count;
    progress_.elapsed_s = elapsed_before + std::chrono::duration<double>(clock::now() - start).count();
    const double run_s = progress_.elapsed_s - elapsed_before;
    const uint32_t run_samples = progress_.samples_done - samples_before;
    progress_.samples_per_s = run_s > 0 ? pixels * run_samples / run_s : 0;
    const double per_sample_s = run_samples > 0 ? run_s / run_samples : 0;
    progress_.eta_s = per_sample_s * (settings_.spp - progress_.samples_done);
    if (settings_.time_limit_s > 0)
      progress_.eta_s = std::min(progress_.eta_s, std::max(0.0, settings_.time_limit_s - progress_.elapsed_s));
    if (settings_.noise_target > 0) progress_.relative_error = film_.relative_error();
    else if (progress_.samples_done >= 2 && (progress_.pass % 4 == 0 || progress_.samples_done >= settings_.spp))
      progress_.relative_error = film_.relative_error();
    RayCounters rays;
    uint64_t nonfinite = 0;
    for (size_t i = 0; i < counters_.size(); ++i) {
      rays += counters_[i];
      nonfinite += nonfinite_[i];
    }
    progress_.rays = rays;
    progress_.nonfinite_samples = nonfinite;
    if (on_pass) on_pass(progress_, film_);
    if (auto r = budget_met()) return *r;
    // Next pass: double, but aim at about two seconds, and do not run far past a time limit.
    const double per_pass_sample_s = pass_s / std::max<uint32_t>(count, 1);
    double target_s = 2.0;
    if (settings_.time_limit_s > 0) target_s = std::min(target_s, settings_.time_limit_s - progress_.elapsed_s);
    uint32_t by_time = per_pass_sample_s > 0 ? static_cast<uint32_t>(std::max(1.0, target_s / per_pass_sample_s)) : 64;
    pass_samples = std::max<uint32_t>(1, std::min({count * 2, by_time, 256u}));
  }
}

}  // namespace tessera
