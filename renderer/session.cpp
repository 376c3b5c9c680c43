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
  }
  return "samples";
}

std::optional<StopReason> stop_reason_from_name(std::string_view name) {
  for (StopReason r : {StopReason::kSamples, StopReason::kTimeLimit, StopReason::kNoiseTarget, StopReason::kStopped,
                       StopReason::kCancelled})
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
  add_aov_layers(film_, aovs, setup.crypto.get());
  progress_.samples_total = settings.spp;
}

void RenderSession::restore(Film film, uint32_t passes, double elapsed_s) {
  if (!film.same_layout(film_)) throw std::invalid_argument("the film to resume has other layers than the render's");
  film_ = std::move(film);
  progress_.pass = passes;
  progress_.samples_done = film_.samples();
  progress_.elapsed_s = elapsed_s;
}

StopReason RenderSession::run(const std::function<void(const RenderProgress&, const Film&)>& on_pass) {
  using clock = std::chrono::steady_clock;
  const auto start = clock::now();
  const double elapsed_before = progress_.elapsed_s;
  const uint32_t samples_before = progress_.samples_done;
  const double pixels = static_cast<double>(settings_.region.width) * settings_.region.height;
  auto budget_met = [&]() -> std::optional<StopReason> {
    if (progress_.samples_done >= settings_.spp) return StopReason::kSamples;
    if (settings_.time_limit_s > 0 && progress_.elapsed_s >= settings_.time_limit_s) return StopReason::kTimeLimit;
    if (settings_.noise_target > 0 && progress_.samples_done >= 4 && progress_.relative_error <= settings_.noise_target)
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
    integrator_->render_pass(settings_.first_sample + first, count, film_, cancel_);
    if (cancel_.load()) return StopReason::kCancelled;
    const double pass_s = std::chrono::duration<double>(clock::now() - pass_start).count();
    {
      const RenderSettings::Region& r = settings_.region;
      film_.set_samples(first + count, r.x, r.y, r.width, r.height);
    }
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
    // An integrator whose film cannot measure its noise reports none (infinity) and never meets a noise target.
    if (!integrator_->measures_noise())
      progress_.relative_error = INFINITY;
    else if (settings_.noise_target > 0)
      progress_.relative_error = film_.relative_error();
    else if (progress_.samples_done >= 2 && (progress_.pass % 4 == 0 || progress_.samples_done >= settings_.spp))
      progress_.relative_error = film_.relative_error();
    progress_.rays = integrator_->rays();
    progress_.nonfinite_samples = integrator_->nonfinite_samples();
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
