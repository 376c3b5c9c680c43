// tessera-render: the local half of the command-line tool, which `tessera render` and `tessera merge` run (the
// `tessera` program itself links no renderer and starts in milliseconds).
//   tessera render JOB.json|SCENE.glb -o out.png [-o out.exr] [-o part.tfilm] [--samples START:COUNT] ...
//   tessera merge part1.tfilm part2.tfilm ... -o out.exr|out.png|out.tfilm
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <map>
#include <optional>
#include <string_view>

#include <nlohmann/json.hpp>

#include "clients/cli/cli_common.h"
#include "clients/cli/fingerprint.h"
#include "clients/cli/partial_film.h"
#include "proto/contract.h"
#include "renderer/aov.h"
#include "renderer/frames.h"
#include "renderer/job.h"
#include "renderer/output.h"
#include "renderer/scene_error.h"

namespace {

using namespace tessera::cli;
using nlohmann::json;

const char* kRenderUsage =
    "usage: tessera render JOB.json|SCENE.glb|SCENE.gltf -o OUT.png|OUT.exr|OUT.tfilm [-o ...] [options]\n"
    "\n"
    "Renders a job document (or a bare scene document, or a glTF asset with its own camera and lights) locally,\n"
    "without a daemon.\n"
    "\n"
    "options:\n"
    "  -o, --output FILE      write the image; the extension picks the format: .png, .exr, or .tfilm (the film's\n"
    "                         raw state, for `tessera merge`)\n"
    "  --spp N                samples per pixel (overrides render.spp)\n"
    "  --samples START:COUNT  render only sample indices [START, START+COUNT) of the job (a render farm task);\n"
    "                         parts merge into exactly the image of one render of all samples (render.spp is\n"
    "                         the whole job's: textures are filtered for that many samples)\n"
    "  --region X,Y,W,H       render only this pixel rectangle (the image keeps its full size)\n"
    "  --width N, --height N  resolution (override render.width/height)\n"
    "  --time-limit S         stop after the pass that crosses S seconds\n"
    "  --adaptive-threshold X per-pixel adaptive sampling: a pixel stops once its error estimate and its\n"
    "                         neighbours' are at most X (render.adaptive_threshold; 0, the default: off)\n"
    "  --min-spp N            with adaptive sampling, the samples every pixel gets before any stops\n"
    "                         (render.min_spp; default 16, or spp when fewer)\n"
    "  --threads N            render threads (default: all hardware threads)\n"
    "  --integrator NAME      path | bdpt | light (render.integrator)\n"
    "  --estimator NAME       mis | area | hemisphere (the path tracer's)\n"
    "  --seed N               random seed\n"
    "  --max-depth N          maximum bounces\n"
    "  --aov NAME             a render pass beside the beauty, in the EXR as NAME.<channel> (repeatable;\n"
    "                         render.aovs): albedo normal depth position uv roughness object_id material_id\n"
    "                         sample_count variance, the light passes (emission, diffuse_direct, ...: README)\n"
    "                         and crypto_object crypto_material (Cryptomatte: CryptoObject00.R, ...)\n"
    "  --denoise NAME         none | regression (render.denoise): the beauty denoised, the rendered one kept in\n"
    "                         the EXR as noisy.<channel>\n"
    "  --variant NAME         the glTF asset's KHR_materials_variants variant (scene.gltf_variant)\n"
    "  --time SECONDS         a still of the glTF asset's animation at this time (scene.time)\n"
    "  --animation NAME|N     the glTF asset's animation to pose, by name or index (scene.animation; default\n"
    "                         the first)\n"
    "  --frames START-END[:STEP]  frames of the animation (render.frames; a frame f at f / render.fps seconds),\n"
    "                         each written to numbered files beside each output: -o out.png writes\n"
    "                         out.0001.png, out.0002.png, ... (padded to the range's widest frame, at least 4)\n"
    "  --shutter OPEN:CLOSE[:STEPS]  motion blur (render.shutter): the shutter open from OPEN to CLOSE frames\n"
    "                         around each frame (a still's: around --time, at render.fps), the animated meshes\n"
    "                         and camera posed at STEPS times over it (default 2; -0.25:0.25 is a 180-degree\n"
    "                         shutter)\n"
    "  -q, --quiet            print nothing but errors and the scene's warnings (no progress bar, no summary)\n"
    "\n"
    "exit codes: 0 done, 1 bad input (fatal), 2 usage, 75 transient failure (retry)\n";

const char* kMergeUsage =
    "usage: tessera merge PART.tfilm [PART.tfilm...] -o OUT.png|OUT.exr|OUT.tfilm [-o ...]\n"
    "\n"
    "Combines partial films written by `tessera render --samples START:COUNT [--region X,Y,W,H] -o PART.tfilm` into\n"
    "the exact image one render of all their samples gives (the film's sums are integers: any order, same bits).\n"
    "The parts must come from the same job and settings (their fingerprints agree), must not overlap (no sample of\n"
    "a pixel twice), and must together give every pixel the same contiguous range of samples: the whole of the\n"
    "job's budget (samples 0 to its render.spp), unless --allow-partial.\n"
    "\n"
    "options:\n"
    "  -o, --output FILE   write the merged image; the extension picks the format (.png, .exr, .tfilm)\n"
    "  --allow-partial     merge parts that leave samples of the budget out (a slice lost, or cut by a time limit):\n"
    "                      the image of the samples there are, noisier than the job's\n";

// A partial film from the file `path` (clients/cli/partial_film.h); fatal when it is not one.
PartialFilm read_film(const std::string& path) {
  return decode_film(read_file(path), path);
}

// ---------------------------------------------------------------------------------------------------------------
// render

// Where a frame range stands: the bar then runs over every frame, its time and ETA those of the whole range.
struct FramesProgress {
  std::string label;     // the frame rendering, as its files number it
  size_t done = 0;       // frames finished
  size_t count = 0;      // frames of the range
  double elapsed_s = 0;  // wall time of the finished frames, their loads included
};

void progress_bar(const tessera::RenderProgress& p, const FramesProgress* frames = nullptr) {
  const int width = 30;
  double frac = p.samples_total ? static_cast<double>(p.samples_done) / p.samples_total : 1.0;
  double elapsed_s = p.elapsed_s, eta_s = p.eta_s;
  std::string head;
  if (frames) {
    frac = (static_cast<double>(frames->done) + frac) / static_cast<double>(frames->count);
    elapsed_s += frames->elapsed_s;
    eta_s = frac > 0 ? elapsed_s / frac * (1 - frac) : 0;
    head =
        "frame " + frames->label + " (" + std::to_string(frames->done + 1) + "/" + std::to_string(frames->count) + ") ";
  }
  int filled = static_cast<int>(frac * width);
  std::string bar(filled, '#');
  bar += std::string(width - filled, '.');
  std::fprintf(stderr, "\r%s[%s] %3.0f%%  %u/%u spp  %.1fs  eta %.1fs  %.2f Msamples/s   ", head.c_str(), bar.c_str(),
               frac * 100, p.samples_done, p.samples_total, elapsed_s, eta_s, p.samples_per_s / 1e6);
  std::fflush(stderr);
}

// --frames START-END[:STEP], or a single frame N, as render.frames; frames may be negative (-10--1).
json frames_option(const std::string& option, const std::string& v) {
  const std::string usage = option + " needs START-END[:STEP] (such as 1-48 or 1-48:2), not \"" + v + "\"";
  const size_t colon = v.find(':');
  const std::string range = v.substr(0, colon);
  const size_t dash = range.find('-', 1);  // the one between the frames: a '-' at the start is a sign
  try {
    json frames = {{"start", parse_integer(option, range.substr(0, dash))},
                   {"end", parse_integer(option, dash == std::string::npos ? range : range.substr(dash + 1))}};
    if (colon != std::string::npos) frames["step"] = parse_integer(option, v.substr(colon + 1));
    return frames;
  } catch (const std::invalid_argument&) {
    throw std::invalid_argument(usage);
  }
}

// --shutter OPEN:CLOSE[:STEPS] as render.shutter: frames relative to the frame, and the motion's time steps.
json shutter_option(const std::string& option, const std::string& v) {
  const std::string usage =
      option + " needs OPEN:CLOSE[:STEPS] (such as -0.25:0.25 or -0.25:0.25:8), not \"" + v + "\"";
  const size_t first = v.find(':');
  if (first == std::string::npos) throw std::invalid_argument(usage);
  const size_t second = v.find(':', first + 1);
  try {
    json shutter = {{"open", parse_number(option, v.substr(0, first))},
                    {"close", parse_number(option, v.substr(first + 1, second - first - 1))}};
    if (second != std::string::npos) shutter["steps"] = parse_integer(option, v.substr(second + 1));
    return shutter;
  } catch (const std::invalid_argument&) {
    throw std::invalid_argument(usage);
  }
}

// Writes the film to every output; the extension picks the format: .tfilm the film itself (the film codec), an
// image format through the output pipeline that the daemon's results go through, each format encoded once. The images
// hold the passes `aovs` (those of the job that rendered the film), or where not given every pass the film holds
// (a merge: the parts do not record which of their layers the job asked for and which its denoiser reads).
void write_outputs(const std::vector<std::string>& outputs, const PartialFilm& part,
                   const std::vector<std::string>* aovs = nullptr) {
  std::vector<tessera::ImageFormat> formats;
  for (const std::string& out : outputs) {
    if (lower_extension(out) == ".tfilm") {
      write_file_atomic(out, encode_film(part));
    } else if (const auto f = tessera::image_format_of(out);
               f && std::find(formats.begin(), formats.end(), *f) == formats.end()) {
      formats.push_back(*f);
    }
  }
  const tessera::OutputPipeline pipeline(tessera::EncodeOptions{part.display, part.exr_half}, formats,
                                         aovs ? *aovs : tessera::aovs_of(part.film, part.sample_count_pass),
                                         part.denoise);
  try {
    pipeline.run(part.film, [&](tessera::ImageFormat format, std::string_view bytes) {
      for (const std::string& out : outputs)
        if (tessera::image_format_of(out) == format) write_file_atomic(out, bytes);
    });
  } catch (const std::exception& e) {
    retry(e.what());
  }
}

// Usage errors (an unknown format) first, then whether every output can be written: all before any work.
void check_outputs(const std::vector<std::string>& outputs) {
  for (const std::string& out : outputs) {
    if (lower_extension(out) != ".tfilm" && !tessera::image_format_of(out))
      throw std::invalid_argument(out + ": unknown output format (use .png, .exr or .tfilm)");
  }
  for (const std::string& out : outputs) check_writable(out);
}

int cmd_render(int argc, char** argv) {
  std::string input;
  std::vector<std::string> outputs;
  json overrides = json::object();
  // The option and value that set each key of `overrides` (render.KEY, "--integrator bpdt"), to say that a refused
  // value is the option's, not the file's.
  std::map<std::string, std::string> option_of;
  int threads = 0;
  bool quiet = false;               // -q: nothing but errors
  const bool progress = isatty(2);  // a progress bar only where someone watches it
  std::optional<std::pair<long long, long long>> samples;
  std::optional<std::vector<long long>> region;
  std::optional<std::string> variant;
  json scene_overrides = json::object();  // --time, --animation
  for (int i = 0; i < argc; ++i) {
    std::string a = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) throw std::invalid_argument(a + " needs a value");
      return argv[++i];
    };
    if (a == "-h" || a == "--help") {
      std::fputs(kRenderUsage, stdout);
      return kExitOk;
    }
    // A render setting given as an option: render.KEY of the job document.
    auto set = [&](const std::string& key, json v) {
      overrides[key] = std::move(v);
      option_of[key] = a + " " + argv[i];  // argv[i]: the value, just read
    };
    if (a == "-o" || a == "--output")
      outputs.push_back(value());
    else if (a == "--spp")
      set("spp", parse_integer(a, value()));
    else if (a == "--samples") {
      auto v = parse_list(a, value(), ':', 2);
      if (v[0] < 0 || v[1] < 1 || v[0] + v[1] > (1ll << 32) - 1)
        throw std::invalid_argument("--samples START:COUNT needs START >= 0 and COUNT >= 1");
      samples = {v[0], v[1]};
    } else if (a == "--region") {
      region = parse_list(a, value(), ',', 4);
    } else if (a == "--width")
      set("width", parse_integer(a, value()));
    else if (a == "--height")
      set("height", parse_integer(a, value()));
    else if (a == "--time-limit")
      set("time_limit_s", parse_number(a, value()));
    else if (a == "--adaptive-threshold")
      set("adaptive_threshold", parse_number(a, value()));
    else if (a == "--min-spp")
      set("min_spp", parse_integer(a, value()));
    else if (a == "--threads")
      threads = static_cast<int>(parse_integer(a, value()));
    else if (a == "--integrator")
      set("integrator", value());
    else if (a == "--estimator")
      set("estimator", value());
    else if (a == "--seed")
      set("seed", parse_integer(a, value()));
    else if (a == "--max-depth")
      set("max_depth", parse_integer(a, value()));
    else if (a == "--aov") {
      json aovs = overrides.value("aovs", json::array());
      aovs.push_back(value());
      option_of["aovs/" + std::to_string(aovs.size() - 1)] = a + " " + aovs.back().get<std::string>();
      overrides["aovs"] = std::move(aovs);
    } else if (a == "--denoise")
      set("denoise", value());
    else if (a == "--variant")
      variant = value();
    else if (a == "--time")
      scene_overrides["time"] = parse_number(a, value());
    else if (a == "--animation")
      scene_overrides["animation"] = animation_choice(value());
    else if (a == "--frames")
      set("frames", frames_option(a, value()));
    else if (a == "--shutter")
      set("shutter", shutter_option(a, value()));
    else if (a == "-q" || a == "--quiet")
      quiet = true;
    else if (!a.empty() && a[0] == '-')
      unknown_option(a, {"--output",  "--spp",       "--samples",    "--region",
                         "--width",   "--height",    "--time-limit", "--adaptive-threshold",
                         "--min-spp", "--threads",   "--integrator", "--estimator",
                         "--seed",    "--max-depth", "--aov",        "--denoise",
                         "--variant", "--time",      "--animation",  "--frames",
                         "--shutter", "--quiet",     "--help"});
    else if (input.empty())
      input = a;
    else
      throw std::invalid_argument("more than one input file");
  }
  if (input.empty()) throw std::invalid_argument("render needs a job file (tessera render -h)");
  if (outputs.empty()) throw std::invalid_argument("render needs at least one -o OUTPUT (tessera render -h)");
  if (samples && overrides.contains("spp")) throw std::invalid_argument("--samples and --spp exclude each other");
  if (overrides.contains("frames") && scene_overrides.contains("time"))
    throw std::invalid_argument("--frames and --time exclude each other (a frame's time is frame / render.fps)");
  check_outputs(outputs);

  json doc;
  const std::string extension = lower_extension(input);
  if (extension == ".glb" || extension == ".gltf") {
    if (!std::ifstream(input)) fatal("cannot open " + input + ": " + std::strerror(errno));
    // A glTF asset renders as the scene of a job that names it (its camera, lights and materials; the files it
    // refers to are read from beside it).
    doc = json{{"kind", "scene"}, {"scene", {{"gltf", std::filesystem::path(input).filename().string()}}}};
  } else {
    doc = parse_json(read_file(input), input);
  }
  // A bare scene document is wrapped into a job; its errors are reported at pointers into the file as written.
  std::string unwrap;
  if (doc.is_object() && !doc.contains("kind") && doc.contains("objects")) {
    doc = json{{"kind", "scene"}, {"scene", doc}};
    unwrap = "/scene";
  }
  auto where = [&](const std::string& pointer) {
    const std::string p = pointer.rfind(unwrap, 0) == 0 ? pointer.substr(unwrap.size()) : pointer;
    return input + ": at " + (p.empty() ? std::string("/") : p) + ": ";
  };
  uint64_t job_spp = 0;  // with --samples: the whole job's samples per pixel
  if (doc.is_object()) {
    if (!doc.contains("render")) doc["render"] = json::object();
    if (doc["render"].is_object()) doc["render"].update(overrides);
    // A sample range is a part of the job's budget: the whole of it must be there for the settings to load. The
    // job's own budget is kept: every slice's rays have the whole job's texture footprints (Camera::pixel_cone).
    if (samples && doc["render"].is_object()) {
      // Render settings the mapping refuses keep the default budget here: the checks below refuse them.
      uint64_t spp = tessera::kDefaultSpp;
      try {
        spp = tessera::render_settings_from_json(doc["render"], "/render", {}).spp;
      } catch (const tessera::SceneError&) {
      }
      job_spp = std::max<uint64_t>(spp, static_cast<uint64_t>(samples->first) + samples->second);
      doc["render"]["spp"] = samples->first + samples->second;
    }
    if (variant && doc.contains("scene") && doc["scene"].is_object()) doc["scene"]["gltf_variant"] = *variant;
    if (doc.contains("scene") && doc["scene"].is_object()) doc["scene"].update(scene_overrides);
  }

  // The daemon's own check, with its messages: the contract's schema (an unknown property such as "albdo" is
  // refused, not rendered with the default), then the renderer's checks in load_job.
  // Asset references name files here, not asset ids: judged as the daemon judges them once a multipart submission
  // has stored their files (whether the file opens is load_job's to say).
  // The option that gave the render setting at `pointer` (/render/KEY, or /render/aovs/I for the I-th --aov), or null:
  // a value an option gave that the job refuses is a usage error naming the option (--integrator bpdt), not an error
  // of the file.
  auto option_at = [&](const std::string& pointer) -> const std::string* {
    const std::string prefix = "/render/";
    if (pointer.rfind(prefix, 0) != 0) return nullptr;
    const std::string key = pointer.substr(prefix.size());
    auto it = option_of.find(key);
    if (it == option_of.end()) it = option_of.find(key.substr(0, key.find('/')));  // /render/frames/end: --frames
    return it == option_of.end() ? nullptr : &it->second;
  };
  json checked = doc;
  const std::vector<std::string> refs = tessera::proto::asset_refs(doc);
  for (const std::string& p : refs) checked[json::json_pointer(p)] = std::string(64, '0');
  if (const auto errors = tessera::proto::contract_schemas().validate_all(checked, "job.schema.json");
      !errors.empty()) {
    // A value an option gave is a usage error naming the option (--integrator bpdt), not an error of the file.
    std::string usage;
    for (const tessera::proto::SchemaError& e : errors)
      if (const std::string* option = option_at(e.pointer))
        usage += (usage.empty() ? "" : "\ntessera: ") + *option + ": " + e.message;
    if (!usage.empty()) throw std::invalid_argument(usage);
    std::string message;
    for (const tessera::proto::SchemaError& e : errors)
      message += (message.empty() ? "" : "\ntessera: ") + where(e.pointer) + e.message;
    // With them, as the daemon answers: the renderer's error on what they leave, or that its checks follow.
    auto rest = tessera::proto::contract_schemas().valid_remainder(checked, "job.schema.json", errors);
    std::string more = input + ": " + std::string(tessera::proto::kChecksPending);
    if (rest && errors.size() < tessera::proto::kMaxReportedErrors) {
      more.clear();
      for (const std::string& p : refs) {  // the files again, not the stand-in ids
        const json::json_pointer pointer{p};
        if (rest->contains(pointer)) (*rest)[pointer] = doc[pointer];
      }
      tessera::JobLoadOptions check;
      check.scene.build = false;  // names, indices and assets; nothing built
      check.scene.asset_root = std::filesystem::absolute(std::filesystem::path(input)).parent_path();
      try {
        tessera::load_job(*rest, check);
      } catch (const tessera::SceneError& e) {
        more = where(e.pointer()) + e.what();
      }
    }
    if (!more.empty()) message += "\ntessera: " + more;
    fatal(message);
  }

  // Loading borrows at most as many extra threads as --threads allows.
  if (threads > 0) tessera::limit_parallel_helpers(threads - 1);
  tessera::JobLoadOptions options;
  // Assets resolve beside the job file; absolute, so that "job.json" in the current directory has a root too.
  options.scene.asset_root = std::filesystem::absolute(std::filesystem::path(input)).parent_path();
  tessera::RenderJob job;
  auto t0 = std::chrono::steady_clock::now();
  try {
    job = tessera::load_job(doc, options);
  } catch (const tessera::SceneError& e) {
    if (const std::string* option = option_at(e.pointer())) throw std::invalid_argument(*option + ": " + e.what());
    fatal(where(e.pointer()) + e.what());
  }
  double load_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  // What the scene could not render as written (an extension ignored, a feature approximated), as the daemon's job
  // status lists them; on stderr even with --quiet.
  for (const std::string& w : job.scene->warnings) std::fprintf(stderr, "tessera: warning: %s\n", w.c_str());

  if (samples) {
    job.settings.first_sample = static_cast<uint32_t>(samples->first);
    job.settings.job_spp = static_cast<uint32_t>(std::min<uint64_t>(job_spp, UINT32_MAX));
    job.settings.spp = static_cast<uint32_t>(samples->second);
  }
  if (region) {
    const auto& r = *region;
    if (r[0] < 0 || r[1] < 0 || r[2] < 1 || r[3] < 1 || r[0] + r[2] > job.settings.width ||
        r[1] + r[3] > job.settings.height)
      fatal("--region " + std::to_string(r[0]) + "," + std::to_string(r[1]) + "," + std::to_string(r[2]) + "," +
            std::to_string(r[3]) + " is not inside the " + std::to_string(job.settings.width) + "x" +
            std::to_string(job.settings.height) + " image");
    job.settings.region = {static_cast<int>(r[0]), static_cast<int>(r[1]), static_cast<int>(r[2]),
                           static_cast<int>(r[3])};
  }

  tessera::ThreadPool pool(threads);
  // Renders `scene` and writes its outputs; `label` marks the summary line of a frame, `frames` the bar's place in a
  // range. `still` is the job document of the still this render is (a frame's: scene.time at the frame's time), whose
  // partial films merge with those of the same still.
  auto render_and_write = [&](std::shared_ptr<const tessera::Scene> scene, const json& still,
                              const tessera::RenderSettings& settings, const std::vector<std::string>& outs,
                              double scene_load_s, const std::string& label, const FramesProgress* frames) {
    tessera::RenderSession session(scene, settings, pool);
    tessera::StopReason reason = session.run([&](const tessera::RenderProgress& p, const tessera::Film&) {
      if (progress && !quiet) progress_bar(p, frames);
    });
    const tessera::RenderProgress& p = session.progress();
    // A frame's bar is cleared (ANSI erase in line) for its summary; the next frame's bar follows it.
    if (progress && !quiet) std::fprintf(stderr, frames ? "\r\x1b[K" : "\n");
    if (!quiet)
      std::fprintf(stderr,
                   "tessera: %s%dx%d, %u spp in %.2fs (load+BVH %.2fs, %zu triangles), %.3g samples/s, %.3g rays/s, "
                   "%d threads, stopped by %s\n",
                   label.c_str(), settings.width, settings.height, p.samples_done, p.elapsed_s, scene_load_s,
                   scene->triangle_count(), p.samples_per_s,
                   p.elapsed_s > 0 ? static_cast<double>(p.rays.total()) / p.elapsed_s : 0.0, pool.size(),
                   tessera::stop_reason_name(reason));

    PartialFilm part;
    part.width = settings.width;
    part.height = settings.height;
    part.first_sample = settings.first_sample;
    part.sample_count = session.film().samples();
    part.job_spp = settings.budget();
    part.region = session.settings().region;
    if (part.region.width <= 0 || part.region.height <= 0) part.region = {0, 0, part.width, part.height};
    part.exr_half = settings.exr_half;
    part.sample_count_pass =
        std::find(settings.aovs.begin(), settings.aovs.end(), "sample_count") != settings.aovs.end();
    part.display = settings.display;
    part.fingerprint = film_fingerprint(still, settings, options.scene.asset_root);
    part.denoise = settings.denoise;
    part.film = session.take_film();
    write_outputs(outs, part, &settings.aovs);
  };
  if (!job.settings.frames) {
    render_and_write(job.scene, doc, job.settings, outputs, load_s, "", nullptr);
    return kExitOk;
  }

  // A frame range: each frame the still at its time (frames.h), rendered and written as a still is, to numbered
  // files. The asset is loaded again for each frame: the importer poses the nodes as it reads them.
  const tessera::FrameRange range = *job.settings.frames;
  const std::vector<int64_t> frame_list = tessera::frame_numbers(range);
  const int padding = tessera::frame_padding(range);
  tessera::RenderSettings still_settings = job.settings;  // a frame's: those of the still at its time
  still_settings.frames.reset();
  // A still's fps matters only to its shutter (in frames at render.fps): without one it is the still's default.
  if (!still_settings.shutter) still_settings.fps = tessera::kDefaultFps;
  // Every frame's files can be written, before the first renders.
  for (const int64_t frame : frame_list)
    for (const std::string& out : outputs) check_writable(tessera::frame_path(out, frame, padding).string());
  std::vector<std::string> warned = job.scene->warnings;
  FramesProgress place;
  place.count = frame_list.size();
  double total_load_s = 0;
  const auto range_t0 = t0;  // from the first frame's load
  for (size_t i = 0; i < frame_list.size(); ++i) {
    const int64_t frame = frame_list[i];
    place.label = tessera::frame_number_text(frame, padding);
    const std::string name = "frame " + place.label;
    const auto frame_t0 = std::chrono::steady_clock::now();
    std::shared_ptr<const tessera::Scene> scene = job.scene;  // load_job loaded the range's first frame
    double frame_load_s = load_s;
    if (i > 0) {
      try {
        scene = tessera::load_frame_scene(doc, job.settings, frame, options.scene);
      } catch (const tessera::SceneError& e) {
        fatal(name + ": " + where(e.pointer()) + e.what());
      }
      frame_load_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - frame_t0).count();
      for (const std::string& w : scene->warnings)
        if (std::find(warned.begin(), warned.end(), w) == warned.end()) {
          std::fprintf(stderr, "tessera: warning: %s: %s\n", name.c_str(), w.c_str());
          warned.push_back(w);
        }
    }
    total_load_s += frame_load_s;
    json still = doc;
    still["scene"] = tessera::frame_scene(doc["scene"], frame, job.settings.fps);
    still["render"].erase("frames");
    if (!still_settings.shutter) still["render"].erase("fps");
    std::vector<std::string> outs;
    for (const std::string& out : outputs) outs.push_back(tessera::frame_path(out, frame, padding).string());
    try {
      render_and_write(scene, still, still_settings, outs, frame_load_s, name + ": ", &place);
    } catch (const Failure& f) {
      throw Failure(f.code, name + ": " + f.what());
    } catch (const std::bad_alloc&) {
      retry(name + ": out of memory");
    } catch (const std::exception& e) {
      retry(name + ": " + e.what());
    }
    ++place.done;
    place.elapsed_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - range_t0).count();
  }
  if (!quiet) {
    const double n = static_cast<double>(frame_list.size());
    std::fprintf(stderr,
                 "tessera: %zu frames (%s to %s) in %.2fs: %.2fs a frame, of which load+BVH %.3fs; %.0f frames/hour\n",
                 frame_list.size(), tessera::frame_path(outputs.front(), frame_list.front(), padding).c_str(),
                 tessera::frame_path(outputs.front(), frame_list.back(), padding).c_str(), place.elapsed_s,
                 place.elapsed_s / n, total_load_s / n, place.elapsed_s > 0 ? 3600 * n / place.elapsed_s : 0.0);
  }
  return kExitOk;
}

// ---------------------------------------------------------------------------------------------------------------
// merge

int cmd_merge(int argc, char** argv) {
  std::vector<std::string> inputs, outputs;
  bool allow_partial = false;
  for (int i = 0; i < argc; ++i) {
    std::string a = argv[i];
    if (a == "-h" || a == "--help") {
      std::fputs(kMergeUsage, stdout);
      return kExitOk;
    }
    if (a == "-o" || a == "--output") {
      if (i + 1 >= argc) throw std::invalid_argument(a + " needs a value");
      outputs.push_back(argv[++i]);
    } else if (a == "--allow-partial") {
      allow_partial = true;
    } else if (!a.empty() && a[0] == '-') {
      unknown_option(a, {"--output", "--allow-partial", "--help"});
    } else {
      inputs.push_back(a);
    }
  }
  if (inputs.empty()) throw std::invalid_argument("merge needs partial films (tessera merge -h)");
  if (outputs.empty()) throw std::invalid_argument("merge needs at least one -o OUTPUT (tessera merge -h)");
  check_outputs(outputs);

  std::vector<PartialFilm> parts;
  for (const std::string& path : inputs) parts.push_back(read_film(path));
  const PartialFilm& first = parts.front();
  auto describe = [](const PartialFilm& p) {
    const auto& r = p.region;
    return p.path + " (samples " + std::to_string(p.first_sample) + ":" + std::to_string(p.sample_count) + ", region " +
           std::to_string(r.x) + "," + std::to_string(r.y) + "," + std::to_string(r.width) + "," +
           std::to_string(r.height) + ")";
  };
  for (const PartialFilm& p : parts) {
    if (p.width != first.width || p.height != first.height)
      fatal("cannot merge " + p.path + " (" + std::to_string(p.width) + "x" + std::to_string(p.height) + ") with " +
            first.path + " (" + std::to_string(first.width) + "x" + std::to_string(first.height) +
            "): different image sizes");
    if (p.fingerprint != first.fingerprint)
      fatal("cannot merge " + p.path + " with " + first.path +
            ": they come from different scenes or render settings (fingerprints differ)");
    if (p.job_spp != first.job_spp)
      fatal("cannot merge " + p.path + " with " + first.path + ": slices of jobs of " + std::to_string(p.job_spp) +
            " and " + std::to_string(first.job_spp) + " samples per pixel (render every slice of one job document)");
  }
  // No sample of a pixel twice.
  for (size_t i = 0; i < parts.size(); ++i) {
    for (size_t j = i + 1; j < parts.size(); ++j) {
      const PartialFilm &a = parts[i], &b = parts[j];
      const bool samples_meet =
          a.first_sample < b.first_sample + b.sample_count && b.first_sample < a.first_sample + a.sample_count;
      const bool regions_meet = a.region.x < b.region.x + b.region.width && b.region.x < a.region.x + a.region.width &&
                                a.region.y < b.region.y + b.region.height && b.region.y < a.region.y + a.region.height;
      if (samples_meet && regions_meet)
        fatal("overlapping parts: " + describe(a) + " and " + describe(b) + " render some samples of the same pixels");
    }
  }
  for (const PartialFilm& p : parts)
    if (!p.film.same_layout(first.film))
      fatal(p.path + " and " + first.path + " hold different film layers (the parts of one job hold the same)");
  // Every pixel must end with the same contiguous range [lo, hi) of samples.
  const size_t n = static_cast<size_t>(first.width) * static_cast<size_t>(first.height);
  std::vector<uint32_t> lo(n, UINT32_MAX), hi(n, 0), total(n, 0);
  for (const PartialFilm& p : parts) {
    if (p.sample_count == 0) fatal(p.path + " holds no samples");
    for (int y = p.region.y; y < p.region.y + p.region.height; ++y) {
      for (int x = p.region.x; x < p.region.x + p.region.width; ++x) {
        const size_t i = static_cast<size_t>(y) * first.width + x;
        lo[i] = std::min(lo[i], p.first_sample);
        hi[i] = std::max(hi[i], p.first_sample + p.sample_count);
        total[i] += p.sample_count;
      }
    }
  }
  for (size_t i = 0; i < n; ++i) {
    const int x = static_cast<int>(i % first.width), y = static_cast<int>(i / first.width);
    const std::string where = "pixel (" + std::to_string(x) + ", " + std::to_string(y) + ")";
    if (total[i] == 0) fatal("the parts do not cover the whole image: no part renders " + where);
    if (lo[i] != lo[0] || hi[i] != hi[0])
      fatal("the parts give " + where + " samples " + std::to_string(lo[i]) + ".." + std::to_string(hi[i]) +
            " but pixel (0, 0) samples " + std::to_string(lo[0]) + ".." + std::to_string(hi[0]) +
            ": every pixel needs the same sample range");
    if (total[i] != hi[i] - lo[i])
      fatal("the parts leave a gap in the samples of " + where + ": they cover " + std::to_string(total[i]) +
            " of samples " + std::to_string(lo[i]) + ".." + std::to_string(hi[i]));
  }

  // The whole budget, or what the user allowed to be missing.
  if (!allow_partial) {
    if (first.job_spp == 0)
      fatal(first.path +
            " does not record its job's samples per pixel (a version 1 film, or a merge of such): whether the "
            "parts cover the job cannot be told (merge with --allow-partial to take the samples they hold)");
    if (lo[0] != 0 || hi[0] != first.job_spp) {
      std::vector<std::string> gaps;
      if (lo[0] > 0) gaps.push_back(std::string("0..").append(std::to_string(lo[0])));
      if (hi[0] < first.job_spp)
        gaps.push_back(std::to_string(hi[0]).append("..").append(std::to_string(first.job_spp)));
      const std::string missing = gaps.size() == 2 ? gaps[0] + " and " + gaps[1] : gaps[0];
      fatal("the parts hold samples " + std::to_string(lo[0]) + ".." + std::to_string(hi[0]) + " of the job's " +
            std::to_string(first.job_spp) + ": samples " + missing +
            " are missing (a slice not given, or cut short by a time limit); merge with --allow-partial for the "
            "image of the samples there are");
    }
  }

  PartialFilm merged;
  merged.width = first.width;
  merged.height = first.height;
  merged.first_sample = lo[0];
  merged.sample_count = hi[0] - lo[0];
  merged.job_spp = first.job_spp;
  merged.region = {0, 0, first.width, first.height};
  merged.exr_half = first.exr_half;
  merged.sample_count_pass = first.sample_count_pass;
  merged.denoise = first.denoise;
  merged.display = first.display;
  merged.fingerprint = first.fingerprint;
  // Every layer's integer sums, hit counts and per-pixel sample counts: exact in any order.
  merged.film = first.film;
  for (size_t i = 1; i < parts.size(); ++i) merged.film.merge(parts[i].film);
  // Film::merge counts every part's samples; parts of different regions share a sample range. Each pixel's own count
  // is its parts' (fewer than the range where adaptive sampling stopped it).
  merged.film.set_schedule_samples(merged.sample_count);
  write_outputs(outputs, merged);
  std::fprintf(stderr, "tessera: merged %zu parts: %dx%d, samples %u..%u\n", parts.size(), merged.width, merged.height,
               merged.first_sample, merged.first_sample + merged.sample_count);
  return kExitOk;
}

}  // namespace

int main(int argc, char** argv) {
  const std::string cmd = argc >= 2 ? argv[1] : "";
  return run_command([&] {
    if (cmd == "render") return cmd_render(argc - 2, argv + 2);
    if (cmd == "merge") return cmd_merge(argc - 2, argv + 2);
    std::fputs(
        "usage: tessera render ... | tessera merge ...  (tessera-render is what these two commands run; see\n"
        "`tessera render -h` and `tessera merge -h`)\n",
        cmd == "-h" || cmd == "--help" ? stdout : stderr);
    return cmd == "-h" || cmd == "--help" ? kExitOk : kExitUsage;
  });
}
