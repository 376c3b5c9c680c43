// How a job renders (RenderSettings) and which files it writes (OutputSpec), and their one mapping to and from JSON.
//
// The JSON side has two readers and one writer. A job document's "render" and "outputs" (proto/schemas/
// render.schema.json, job.schema.json) are read with every check the schema cannot make (the server's configured
// limits, integrators that exist) and defaults for what they leave out. The writer gives the normalised form: every
// field the document can set, defaults filled in, names for the enumerations; its text is what a job record stores
// (JobRecord::settings, JobRecord::outputs), and the job status shows it. The stored text is read back by the
// document reader, so that a record written by an earlier version, with fewer fields, takes the defaults for the
// rest, as a document would.
//
// The names of every enumeration a document spells out (sampler, estimator, tone curve, EXR precision, output format,
// denoiser)
// are tables in render_settings.cpp, read both ways; the integrators' names are their registry's (integrator.h).
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include "renderer/display.h"
#include "renderer/frames.h"
#include "renderer/integrator.h"
#include "renderer/sampler.h"

namespace tessera {

// A post stage that denoises the beauty (denoise.h); kNone leaves it as rendered.
enum class Denoiser { kNone, kRegression };

struct RenderSettings {
  int width = 512;
  int height = 512;
  uint32_t spp = 64;  // samples per pixel budget
  uint64_t seed = 0;
  SamplerKind sampler = SamplerKind::kSobol;
  IntegratorSettings integrator;  // which integrator renders, and its settings
  double time_limit_s = 0;        // stop after the pass that crosses this; 0: none
  double noise_target = 0;        // stop when Film::relative_error() falls below; 0: none
  // Per-pixel adaptive sampling (adaptive.h): a pixel stops once its error estimate and its neighbours' are at most
  // this; 0: off, every pixel gets spp samples.
  double adaptive_threshold = 0;
  uint32_t min_spp = 16;    // with adaptive sampling, the samples every pixel gets before any stops (default_min_spp)
  DisplaySettings display;  // for PNG outputs and previews
  bool exr_half = true;     // EXR channel precision
  // The render passes beside the beauty (aov.h), by name, in the order of aov_table(): each once.
  std::vector<std::string> aovs;
  Denoiser denoise = Denoiser::kNone;  // the beauty denoised, the rendered one kept as the layer "noisy"
  // A range of frames of the scene's animation (frames.h), each the still at its time; none: one still.
  std::optional<FrameRange> frames;
  double fps = kDefaultFps;  // frames per second: frame f is at f / fps seconds (plus scene.time_offset)
  // Motion blur (frames.h): the interval around each frame (a still's scene.time) that the camera's samples spread
  // over, in frames at fps; none: every sample at the frame's time.
  std::optional<Shutter> shutter;

  // Set by whoever renders a part of a job, never by a document (not in the JSON mapping); integrator.rr_start_depth
  // neither.
  uint32_t first_sample = 0;  // render sample indices [first_sample, first_sample + spp): a range of a larger job
  uint32_t job_spp = 0;       // that larger job's samples per pixel (rays' texture footprints depend on it); 0: spp
  // The whole job's sample budget: samples [0, budget) of every pixel make its image.
  uint32_t budget() const { return job_spp ? job_spp : first_sample + spp; }
  // Crop window in pixels (render only these; the film keeps the full size). Empty (w or h 0): the whole image.
  using Region = PixelRegion;
  Region region;
  int tile_size = 32;

  bool operator==(const RenderSettings&) const = default;
};

// The result files a job writes.
struct OutputSpec {
  bool png = true;
  bool exr = true;

  bool operator==(const OutputSpec&) const = default;
};

// render.spp when the job does not say (the contract's default).
constexpr uint32_t kDefaultSpp = 64;

// render.min_spp when the job does not say: 16, or spp when that is fewer (render_settings.cpp says why).
uint32_t default_min_spp(uint32_t spp);

// The largest settings a server takes; the defaults are the contract's maxima (render.schema.json).
struct RenderLimits {
  int max_width = 8192;
  int max_height = 8192;
  uint32_t max_spp = 1u << 16;
  int max_depth = 1024;
  int max_volume_depth = 4096;
  uint64_t max_frames = 10000;  // frames of one render.frames range
};

// The passes the film of a job with `settings` holds: render.aovs and those the output pipeline's stages read (the
// denoiser's features), in the order of aov_table(). The images keep render.aovs alone.
std::vector<std::string> film_aovs(const RenderSettings& settings);

// A document's "render" object (`pointer` is its JSON pointer, "/render" in a job): defaults for absent keys, null
// for none at all. Throws SceneError naming the field.
RenderSettings render_settings_from_json(const nlohmann::json& render, const std::string& pointer,
                                         const RenderLimits& limits);
// The settings a material preview (a "material" job) takes where its document leaves them out: adaptive sampling at
// kPreviewAdaptiveThreshold and the regression denoiser, as far as the document's integrator can do them (path; bdpt
// and light neither): a preview is looked at within a second (the threshold's measured cost and gain: README, Material
// jobs). `render` is the document's "render"
// (null: none); the result is the "render" to read with render_settings_from_json, so the job's settings hold both
// explicitly and its stored record keeps them whatever the defaults become.
inline constexpr double kPreviewAdaptiveThreshold = 0.05;
nlohmann::json with_preview_defaults(const nlohmann::json& render);
// The normalised form: every field a document can set, defaults filled in (but max_volume_depth, subsurface_guiding,
// aovs, denoise, frames, fps and shutter only where they are not their defaults, so that records written before they
// existed keep their text).
nlohmann::json render_settings_to_json(const RenderSettings& settings);
// The same as the job status shows it: a stopping rule that is off (time_limit_s, noise_target at 0, the documents'
// default) is left out, as a document leaves it out, so that it reads as "none" rather than as a limit of zero.
nlohmann::json render_settings_status_json(const RenderSettings& settings);

// A document's "outputs" array (`pointer` its JSON pointer); a document without one asks for OutputSpec{}, both
// formats. Throws SceneError.
OutputSpec output_spec_from_json(const nlohmann::json& outputs, const std::string& pointer);
// The normalised form: the formats' names, in the order png, exr.
nlohmann::json output_spec_to_json(const OutputSpec& outputs);

// The text a job record stores, and the settings it holds. The readers take the text of any version (older ones
// wrote fewer fields) and throw std::runtime_error for text that is not such a record's.
std::string render_settings_text(const RenderSettings& settings);
RenderSettings render_settings_from_text(std::string_view text);
std::string output_spec_text(const OutputSpec& outputs);
OutputSpec output_spec_from_text(std::string_view text);

// The names documents give them.
const char* sampler_name(SamplerKind sampler);
const char* estimator_name(Estimator estimator);
const char* tonemap_name(ToneMap tonemap);
const char* denoiser_name(Denoiser denoiser);
// The passes (aov.h names) denoiser `d` reads, which the film records whatever render.aovs names; none for
// Denoiser::kNone.
const std::vector<std::string>& denoiser_features(Denoiser d);

}  // namespace tessera
