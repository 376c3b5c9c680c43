#include "server/jobs/job_results.h"

#include <random>
#include <stdexcept>
#include <utility>

#include "renderer/render_settings.h"
#include "server/base/log.h"
#include "server/base/time_format.h"
#include "server/jobs/checkpoint.h"

namespace tessera::server {

uint64_t unit_settings_hash(const std::string& settings, int unit) {
  return fnv1a64(std::to_string(unit), fnv1a64(settings));
}

JobResults::JobResults(JobStore& store, const JobFiles& files, std::string node)
    : store_(store), files_(files), log_(files, std::move(node)) {}

std::string stage_outputs(const JobFiles& files, const std::string& id, const OutputPipeline& outputs,
                          const Image& image, int64_t key) {
  std::string written;
  auto stage = [&](JobFile f, std::string_view bytes) {
    files.stage(id, f, key, bytes);
    (written += ' ') += job_file_name(f);
  };
  outputs.publish(image, [&](ImageFormat format, std::string_view bytes) { stage(result_file(format), bytes); });
  outputs.publish_passes(image, [&](std::string_view pass, std::string_view png) {
    if (const auto f = pass_file(pass)) stage(*f, png);
  });
  return written;
}

void JobResults::settle_staged(const std::string& id, int64_t key, bool publish) const {
  for (JobFile f : kResultFiles) {
    try {
      if (publish)
        files_.publish_staged(id, f, key);
      else
        files_.discard_staged(id, f, key);
    } catch (const std::exception& e) {
      log(LogLevel::kWarn, "cannot settle the staged results of a job", {{"job", id}, {"error", e.what()}});
    }
  }
}

std::optional<Film> JobResults::merge_unit_films(const JobRecord& job, int width, int height, bool in_progress) const {
  std::optional<Film> merged;
  for (const UnitRecord& u : store_.units(job.id)) {
    if ((!u.done && !in_progress) || u.checkpoint_epoch == 0) continue;
    auto bytes = files_.read_unit(job.id, u.index, u.checkpoint_epoch);
    auto cp =
        bytes ? decode_checkpoint(*bytes, width, height, unit_settings_hash(job.settings, u.index)) : std::nullopt;
    if (!cp || (u.done && cp->film.samples() != u.samples)) {
      if (!u.done) continue;  // a checkpoint being replaced; the next one will do
      throw std::runtime_error("the film of unit " + std::to_string(u.index + 1) + " is missing or damaged");
    }
    // Every layer's integer sums and the per-pixel counts: exact in any order (film.h).
    if (!merged)
      merged = std::move(cp->film);
    else
      merged->merge(cp->film);
  }
  return merged;
}

bool JobResults::record_cancel(const JobRecord& job) const {
  const int64_t key = -static_cast<int64_t>(std::random_device{}() | 1u);
  stage_partial_results(job, key);
  bool taken = false;
  try {
    taken = store_.transition(job.id, JobState::kCancelled, now_ms(), "cancelled");
  } catch (const JobStoreError&) {
    settle_staged(job.id, key, false);  // nothing of a cancel the store did not take is left staged
    throw;
  }
  settle_staged(job.id, key, taken);
  return taken;
}

void JobResults::stage_partial_results(const JobRecord& job, int64_t key) const {
  try {
    const RenderSettings settings = render_settings_from_text(job.settings);
    std::optional<Film> film;
    uint32_t passes = 0;
    if (auto bytes = files_.read(job.id, JobFile::kCheckpoint)) {
      if (auto cp = decode_checkpoint(*bytes, settings.width, settings.height, fnv1a64(job.settings))) {
        film = std::move(cp->film);
        passes = cp->passes;
      }
    } else {
      // A split job: what its units rendered.
      film = merge_unit_films(job, settings.width, settings.height, true);
    }
    if (!film || film->samples() == 0) return;
    const OutputPipeline outputs(settings, output_spec_from_text(job.outputs));
    const std::string written = stage_outputs(files_, job.id, outputs, outputs.image(*film), key);
    log_.add(job.id, "kept what it rendered, " + std::to_string(film->samples()) + " spp in " + std::to_string(passes) +
                         " passes, as its partial results (once the cancel is taken):" + written);
  } catch (const std::exception& e) {
    log(LogLevel::kWarn, "cannot write the partial results of a cancelled job", {{"job", job.id}, {"error", e.what()}});
    log_.add(job.id, std::string("warning: its partial results cannot be written: ") + e.what());
  }
}

}  // namespace tessera::server
