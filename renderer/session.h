// A progressive render: each pass, the settings' integrator (integrator.h) adds samples to every pixel of the region
// on the thread pool, or with adaptive sampling (adaptive.h) to the pixels still sampling. After each pass the caller
// gets the progress and the film (for a preview and a checkpoint). Sampling is deterministic in (seed, pixel, sample
// index), and adaptive sampling decides only at sample counts fixed by the job (passes end on them), so the image
// after N samples is the same whatever the thread count, the pass sizes, or a resume from a checkpoint.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string_view>
#include <utility>

#include "renderer/adaptive.h"
#include "renderer/camera.h"
#include "renderer/film.h"
#include "renderer/integrator.h"
#include "renderer/render_settings.h"
#include "renderer/sampler.h"
#include "renderer/thread_pool.h"

namespace tessera {

class Scene;

// kAdaptiveThreshold: adaptive sampling stopped every pixel before spp.
enum class StopReason { kSamples, kTimeLimit, kNoiseTarget, kStopped, kCancelled, kAdaptiveThreshold };
const char* stop_reason_name(StopReason r);
std::optional<StopReason> stop_reason_from_name(std::string_view name);

struct RenderProgress {
  uint32_t pass = 0;           // passes completed
  uint32_t samples_done = 0;   // per pixel: the mean over the region's pixels, rounded down
  uint32_t samples_total = 0;  // per pixel, the spp budget
  double elapsed_s = 0;        // render time, including time before a resume
  // Estimated seconds to the end of the budget: the pixels still sampling given the rest of it (with adaptive
  // sampling, an upper bound), at this run's time per pixel sample.
  double eta_s = 0;
  double samples_per_s = 0;   // pixel samples rendered per second over this run (with adaptive sampling, the pixels')
  double relative_error = 0;  // Film::relative_error() (infinity before 2 samples)
  RayCounters rays;           // totals since the start (or the resume)
  uint64_t nonfinite_samples = 0;
};

class RenderSession {
 public:
  // Throws std::invalid_argument when the settings' integrator does not exist or cannot render the scene.
  RenderSession(std::shared_ptr<const Scene> scene, const RenderSettings& settings, ThreadPool& pool);

  // Continues from a checkpoint: `film` holds the state after `passes` passes and `elapsed_s` seconds.
  void restore(Film film, uint32_t passes, double elapsed_s);

  // Renders until a budget is met, stop() or cancel(). `on_pass` runs on the calling thread after every pass.
  StopReason run(const std::function<void(const RenderProgress&, const Film&)>& on_pass = {});

  // From any thread: stop() ends the render after the pass under way (its film is complete and valid);
  // cancel() abandons it within one tile's time (the film is then incomplete).
  void stop() { stop_.store(true); }
  void cancel() { cancel_.store(true); }

  const Film& film() const { return film_; }
  // The film, moved out of a session that is done (a film of many passes is gigabytes: not copied).
  Film take_film() { return std::move(film_); }
  const RenderSettings& settings() const { return settings_; }
  const RenderProgress& progress() const { return progress_; }

 private:
  std::shared_ptr<const Scene> scene_;
  RenderSettings settings_;
  Film film_;
  RenderProgress progress_;
  std::unique_ptr<Integrator> integrator_;
  AdaptiveSampling adaptive_;
  PixelMask active_;         // with adaptive sampling, the pixels the next pass samples
  size_t active_count_ = 0;  // how many
  // With adaptive sampling: the pixels of the next pass, from the film; a film whose pixels have all stopped ends its
  // schedule (Film::set_schedule_samples spp).
  void update_active();
  // The sum over the region's pixels of their sample counts.
  uint64_t pixel_samples_total() const;
  std::atomic<bool> stop_{false};
  std::atomic<bool> cancel_{false};
};

}  // namespace tessera
