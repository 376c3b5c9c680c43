#include "renderer/session.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <optional>

#include "renderer/aov.h"
#include "renderer/scene.h"

namespace tessera {

const char* stop_reason_name(StopReason r) {
  switch (r) {
    case StopReason::kSamples:
      return "samples";
    case StopReason::kTimeLimit:
      return "time_limit";
    case StopReason::kNoiseTarget:
      return "noise_target";
    case StopReason::kStopped:
      return "stopped";
    case StopReason::kCancelled:
      return "cancelled";
    case StopReason::kAdaptiveThreshold:
      return "adaptive_threshold";
  }
  return "samples";
}

std::optional<StopReason> stop_reason_from_name(std::string_view name) {
  for (StopReason r : {StopReason::kSamples, StopReason::kTimeLimit, StopReason::kNoiseTarget, StopReason::kStopped,
                       StopReason::kCancelled, StopReason::kAdaptiveThreshold})
    if (name == stop_reason_name(r)) return r;
  return std::nullopt;
}

RenderSession::RenderSession(std::shared_ptr<const Scene> scene, const RenderSettings& settings, ThreadPool& pool)
    : scene_(std::move(scene)), settings_(settings), film_(settings.width, settings.height) {
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
  IntegratorSetup setup;
  setup.scene = scene_;
  setup.camera = Camera(scene_->camera, settings.width, settings.height);
  setup.width = settings.width;
  setup.height = settings.height;
  setup.region = settings_.region;
  setup.seed = settings.seed;
  setup.sampler = settings.sampler;
  setup.settings = settings.integrator;
  setup.samples_per_pixel = settings.job_spp ? settings.job_spp : settings.spp;
  setup.tile_size = settings.tile_size;
  setup.pool = &pool;
  const std::vector<std::string> aovs = film_aovs(settings);
  for (const AovInfo* layer : aov_layers(aovs))
    if (layer->source == AovSource::kCryptomatte) {
      setup.crypto =
          std::make_shared<const cryptomatte::Ids>(cryptomatte::ids_of(scene_->object_names(), scene_->material_names));
      break;
    }
  integrator_ = IntegratorRegistry::builtin().create(setup);
  for (const std::string& aov : settings.aovs)
    if (std::string problem = integrator_aov_problem(settings.integrator.name, aov); !problem.empty())
      throw std::invalid_argument(problem);
  adaptive_ = AdaptiveSampling(settings_);
  if (adaptive_.enabled())
    if (std::string problem = integrator_adaptive_problem(settings.integrator.name); !problem.empty())
      throw std::invalid_argument(problem);
  add_aov_layers(film_, aovs, setup.crypto.get());
  progress_.samples_total = settings.spp;
  update_active();
}

void RenderSession::update_active() {
  const RenderSettings::Region& r = settings_.region;
  active_count_ = static_cast<size_t>(r.width) * static_cast<size_t>(r.height);
  if (!adaptive_.enabled()) return;
  active_count_ = adaptive_.active_pixels(film_, r, active_);
  if (active_count_ == 0 && film_.samples() < settings_.spp) film_.set_schedule_samples(settings_.spp);
}

uint64_t RenderSession::pixel_samples_total() const {
  uint64_t total = 0;
  for (uint32_t n : film_.pixel_sample_counts()) total += n;
  return total;
}

void RenderSession::restore(Film film, uint32_t passes, double elapsed_s) {
  if (!film.same_layout(film_)) throw std::invalid_argument("the film to resume has other layers than the render's");
  film_ = std::move(film);
  progress_.pass = passes;
  progress_.elapsed_s = elapsed_s;
  const double pixels = static_cast<double>(settings_.region.width) * settings_.region.height;
  progress_.samples_done = pixels > 0 ? static_cast<uint32_t>(pixel_samples_total() / pixels) : film_.samples();
  update_active();
}

StopReason RenderSession::run(const std::function<void(const RenderProgress&, const Film&)>& on_pass) {
  using clock = std::chrono::steady_clock;
  const auto start = clock::now();
  const double elapsed_before = progress_.elapsed_s;
  const uint64_t pixel_samples_before = pixel_samples_total();
  const double pixels = static_cast<double>(settings_.region.width) * settings_.region.height;
  auto budget_met = [&]() -> std::optional<StopReason> {
    if (film_.samples() >= settings_.spp) {
      // Adaptive sampling ended the schedule when no pixel reached spp.
      if (adaptive_.enabled())
        for (uint32_t n : film_.pixel_sample_counts())
          if (n >= settings_.spp) return StopReason::kSamples;
      return adaptive_.enabled() ? StopReason::kAdaptiveThreshold : StopReason::kSamples;
    }
    if (settings_.time_limit_s > 0 && progress_.elapsed_s >= settings_.time_limit_s) return StopReason::kTimeLimit;
    if (settings_.noise_target > 0 && film_.samples() >= 4 && progress_.relative_error <= settings_.noise_target)
      return StopReason::kNoiseTarget;
    return std::nullopt;
  };
  if (auto r = budget_met()) return *r;
  // Passes start at one sample and grow geometrically, so the first preview comes fast and later passes amortise
  // the per-pass work (previews, checkpoints); a pass is kept near two seconds so previews stay fresh. With adaptive
  // sampling a pass ends at the next decision point at the latest.
  uint32_t pass_samples = 1;
  for (;;) {
    if (cancel_.load()) return StopReason::kCancelled;
    if (stop_.load()) return StopReason::kStopped;
    const uint32_t first = film_.samples();
    const uint32_t count =
        std::min({pass_samples, settings_.spp - first, adaptive_.next_decision_point(first) - first});
    const auto pass_start = clock::now();
    integrator_->render_pass(settings_.first_sample + first, count, film_, cancel_,
                             adaptive_.enabled() ? &active_ : nullptr);
    if (cancel_.load()) return StopReason::kCancelled;
    const double pass_s = std::chrono::duration<double>(clock::now() - pass_start).count();
    const double pass_pixels = static_cast<double>(active_count_);
    if (adaptive_.enabled()) {
      film_.advance_samples(count, active_);
      update_active();
    } else {
      const RenderSettings::Region& r = settings_.region;
      film_.set_samples(first + count, r.x, r.y, r.width, r.height);
    }
    const uint64_t pixel_samples = pixel_samples_total();
    progress_.pass += 1;
    progress_.samples_done = pixels > 0 ? static_cast<uint32_t>(pixel_samples / pixels) : film_.samples();
    progress_.elapsed_s = elapsed_before + std::chrono::duration<double>(clock::now() - start).count();
    const double run_s = progress_.elapsed_s - elapsed_before;
    const double run_pixel_samples = static_cast<double>(pixel_samples - pixel_samples_before);
    progress_.samples_per_s = run_s > 0 ? run_pixel_samples / run_s : 0;
    const double per_pixel_sample_s = run_pixel_samples > 0 ? run_s / run_pixel_samples : 0;
    progress_.eta_s = per_pixel_sample_s * static_cast<double>(active_count_) *
                      static_cast<double>(settings_.spp - std::min(film_.samples(), settings_.spp));
    if (settings_.time_limit_s > 0)
      progress_.eta_s = std::min(progress_.eta_s, std::max(0.0, settings_.time_limit_s - progress_.elapsed_s));
    // An integrator whose film cannot measure its noise reports none (infinity) and never meets a noise target.
    if (!integrator_->measures_noise())
      progress_.relative_error = INFINITY;
    else if (settings_.noise_target > 0)
      progress_.relative_error = film_.relative_error();
    else if (film_.samples() >= 2 && (progress_.pass % 4 == 0 || film_.samples() >= settings_.spp))
      progress_.relative_error = film_.relative_error();
    progress_.rays = integrator_->rays();
    progress_.nonfinite_samples = integrator_->nonfinite_samples();
    if (on_pass) on_pass(progress_, film_);
    if (auto r = budget_met()) return *r;
    // Next pass: double, but aim at about two seconds, and do not run far past a time limit.
    const double per_pass_sample_s = pass_s / std::max<uint32_t>(count, 1);
    // With adaptive sampling the next pass samples fewer pixels (or as many), each sample of it the faster.
    const double pass_sample_s =
        pass_pixels > 0 ? per_pass_sample_s * static_cast<double>(active_count_) / pass_pixels : per_pass_sample_s;
    double target_s = 2.0;
    if (settings_.time_limit_s > 0) target_s = std::min(target_s, settings_.time_limit_s - progress_.elapsed_s);
    uint32_t by_time = pass_sample_s > 0 ? static_cast<uint32_t>(std::max(1.0, target_s / pass_sample_s)) : 64;
    pass_samples = std::max<uint32_t>(1, std::min({count * 2, by_time, 256u}));
  }
}

}  // namespace tessera
