// tessera-render: the local half of the command-line tool, which `tessera render` and `tessera merge` run (the
// `tessera` program itself links no renderer and starts in milliseconds).
//   tessera render JOB.json|SCENE.glb -o out.png [-o out.exr] [-o part.tfilm] [--samples START:COUNT] ...
//   tessera merge part1.tfilm part2.tfilm ... -o out.exr|out.png|out.tfilm
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <optional>
#include <set>
#include <string_view>

#include <nlohmann/json.hpp>

#include "clients/cli/cli_common.h"
#include "proto/contract.h"
#include "renderer/image_io.h"
#include "renderer/job.h"
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
    "  --threads N            render threads (default: all hardware threads)\n"
    "  --integrator NAME      path | bdpt | light (render.integrator)\n"
    "  --estimator NAME       mis | area | hemisphere (the path tracer's)\n"
    "  --seed N               random seed\n"
    "  --max-depth N          maximum bounces\n"
    "  --variant NAME         the glTF asset's KHR_materials_variants variant (scene.gltf_variant)\n"
    "  -q, --quiet            no progress bar\n"
    "\n"
    "exit codes: 0 done, 1 bad input (fatal), 2 usage, 75 transient failure (retry)\n";

const char* kMergeUsage =
    "usage: tessera merge PART.tfilm [PART.tfilm...] -o OUT.png|OUT.exr|OUT.tfilm [-o ...]\n"
    "\n"
    "Combines partial films written by `tessera render --samples START:COUNT [--region X,Y,W,H] -o PART.tfilm` into\n"
    "the exact image one render of all their samples gives (the film's sums are integers: any order, same bits).\n"
    "The parts must come from the same job and settings (their fingerprints agree), must not overlap (no sample of\n"
    "a pixel twice), and must together give every pixel the same contiguous range of samples.\n";

// ---------------------------------------------------------------------------------------------------------------
// Partial films (.tfilm)
//
// A partial film is the raw state of a Film after rendering sample indices [first_sample, first_sample + count)
// of a job, optionally for a pixel region only. All fields little-endian:
//
//   offset  size  field
//        0     8  magic "TSRFILM\n"
//        8     4  u32 version (1)
//       12     4  i32 width            the full image
//       16     4  i32 height
//       20     4  u32 first_sample     the range's first sample index
//       24     4  u32 sample_count     samples every pixel of the region received (a time limit may cut a range)
//       28    16  i32 x, y, w, h       the region rendered (the whole image when not cropped)
//       44     4  u32 flags            bit 0: the job's EXR output is half precision
//       48     4  f32 exposure_ev      the job's display settings, for PNG outputs of a merge
//       52     4  u32 tonemap          0 clamp, 1 ACES
//       56     8  u64 fingerprint      FNV-1a of the scene and the settings the pixels depend on (not the sample
//                                      range, region, time limit or display): parts of different jobs never merge
//       64  52·N  the film's state (Film::append_state; zero outside the region): 3 × i128 per pixel (R, G, B),
//                 row-major from the top left, fixed point in units of 2^-40, then an f32 per pixel, its sum of
//                 squared luminance (for the noise estimate only)
//
// with N = width × height. The file size is checked exactly.

constexpr char kFilmMagic[8] = {'T', 'S', 'R', 'F', 'I', 'L', 'M', '\n'};
constexpr uint32_t kFilmVersion = 1;
constexpr size_t kFilmHeader = 64;

struct PartialFilm {
  int width = 0, height = 0;
  uint32_t first_sample = 0, sample_count = 0;
  tessera::RenderSettings::Region region;
  bool exr_half = true;
  tessera::DisplaySettings display;
  uint64_t fingerprint = 0;
  tessera::Film film;
  std::string path;  // where it was read from, for messages
};

template <typename T>
void put(std::string& out, T v) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  out.append(b, sizeof(T));
}
template <typename T>
T get(const std::string& in, size_t offset) {
  T v;
  std::memcpy(&v, in.data() + offset, sizeof(T));
  return v;
}

std::string encode_film(const PartialFilm& p) {
  static_assert(sizeof(tessera::FixedSum) == 16);  // the layout above
  std::string out;
  out.reserve(kFilmHeader + tessera::Film::state_size(p.width, p.height));
  out.append(kFilmMagic, 8);
  put<uint32_t>(out, kFilmVersion);
  put<int32_t>(out, p.width);
  put<int32_t>(out, p.height);
  put<uint32_t>(out, p.first_sample);
  put<uint32_t>(out, p.sample_count);
  put<int32_t>(out, p.region.x);
  put<int32_t>(out, p.region.y);
  put<int32_t>(out, p.region.width);
  put<int32_t>(out, p.region.height);
  put<uint32_t>(out, p.exr_half ? 1u : 0u);
  put<float>(out, p.display.exposure_ev);
  put<uint32_t>(out, p.display.tonemap == tessera::ToneMap::kAces ? 1u : 0u);
  put<uint64_t>(out, p.fingerprint);
  p.film.append_state(out);
  return out;
}

PartialFilm decode_film(const std::string& path) {
  const std::string in = read_file(path);
  if (in.size() < kFilmHeader || std::memcmp(in.data(), kFilmMagic, 8) != 0)
    fatal(path + " is not a tessera partial film (.tfilm)");
  if (uint32_t v = get<uint32_t>(in, 8); v != kFilmVersion)
    fatal(path + ": partial film version " + std::to_string(v) + " (this tessera reads version 1)");
  PartialFilm p;
  p.path = path;
  p.width = get<int32_t>(in, 12);
  p.height = get<int32_t>(in, 16);
  p.first_sample = get<uint32_t>(in, 20);
  p.sample_count = get<uint32_t>(in, 24);
  p.region = {get<int32_t>(in, 28), get<int32_t>(in, 32), get<int32_t>(in, 36), get<int32_t>(in, 40)};
  p.exr_half = (get<uint32_t>(in, 44) & 1u) != 0;
  p.display.exposure_ev = get<float>(in, 48);
  p.display.tonemap = get<uint32_t>(in, 52) == 1 ? tessera::ToneMap::kAces : tessera::ToneMap::kClamp;
  p.fingerprint = get<uint64_t>(in, 56);
  if (p.width < 1 || p.height < 1 || p.width > 65536 || p.height > 65536) fatal(path + ": bad image size");
  const auto& r = p.region;
  if (r.x < 0 || r.y < 0 || r.width < 1 || r.height < 1 || r.x + r.width > p.width || r.y + r.height > p.height)
    fatal(path + ": region outside the image");
  if (in.size() != kFilmHeader + tessera::Film::state_size(p.width, p.height))
    fatal(path + ": truncated or oversized (" + std::to_string(in.size()) + " bytes for " + std::to_string(p.width) +
          "x" + std::to_string(p.height) + ")");
  p.film = tessera::Film(p.width, p.height);
  p.film.read_state(std::string_view(in).substr(kFilmHeader));  // the size is checked above
  p.film.set_samples(p.sample_count);
  return p;
}

uint64_t fnv1a(uint64_t h, std::string_view bytes) {
  for (unsigned char c : bytes) {
    h ^= c;
    h *= 0x100000001b3ull;
  }
  return h;
}

// The same over a file's bytes, read a megabyte at a time (an environment map can be hundreds of megabytes).
uint64_t fnv1a_file(uint64_t h, const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) fatal("cannot open " + path.string() + ": " + std::strerror(errno));
  std::vector<char> chunk(1 << 20);
  while (in) {
    in.read(chunk.data(), static_cast<std::streamsize>(chunk.size()));
    h = fnv1a(h, std::string_view(chunk.data(), static_cast<size_t>(in.gcount())));
  }
  if (in.bad()) fatal("cannot read " + path.string());
  return h;
}

// Asset files a document names ("gltf", "map", "texture" strings) and that exist beside the job: their bytes are
// part of the fingerprint.
void collect_assets(const json& v, std::set<std::string>* out) {
  if (v.is_object()) {
    for (const auto& [key, value] : v.items()) {
      if ((key == "gltf" || key == "map" || key == "texture") && value.is_string())
        out->insert(value.get<std::string>());
      collect_assets(value, out);
    }
  } else if (v.is_array()) {
    for (const json& e : v) collect_assets(e, out);
  }
}

uint64_t fingerprint(const json& doc, const tessera::RenderSettings& s, const std::filesystem::path& asset_root) {
  json scene = doc;
  for (const char* key : {"render", "outputs", "priority"}) scene.erase(key);
  json settings = {{"width", s.width},
                   {"height", s.height},
                   {"seed", s.seed},
                   {"sampler", static_cast<int>(s.sampler)},
                   {"integrator", s.integrator.name},
                   {"estimator", static_cast<int>(s.integrator.estimator)},
                   {"max_depth", s.integrator.max_depth},
                   {"rr_start_depth", s.integrator.rr_start_depth}};
  uint64_t h = 0xcbf29ce484222325ull;
  h = fnv1a(h, scene.dump());
  h = fnv1a(h, settings.dump());
  std::set<std::string> assets;
  collect_assets(doc, &assets);
  for (const std::string& a : assets) {
    std::error_code ec;
    const auto file = asset_root / a;
    if (std::filesystem::is_regular_file(file, ec)) h = fnv1a_file(fnv1a(h, a), file);
  }
  return h;
}

// ---------------------------------------------------------------------------------------------------------------
// render

void progress_bar(const tessera::RenderProgress& p) {
  const int width = 30;
  double frac = p.samples_total ? static_cast<double>(p.samples_done) / p.samples_total : 1.0;
  int filled = static_cast<int>(frac * width);
  std::string bar(filled, '#');
  bar += std::string(width - filled, '.');
  std::fprintf(stderr, "\r[%s] %3.0f%%  %u/%u spp  %.1fs  eta %.1fs  %.2f Msamples/s   ", bar.c_str(), frac * 100,
               p.samples_done, p.samples_total, p.elapsed_s, p.eta_s, p.samples_per_s / 1e6);
  std::fflush(stderr);
}

// Writes the film (or its resolved image) to every output; the extension picks the format.
void write_outputs(const std::vector<std::string>& outputs, const PartialFilm& part) {
  std::vector<float> rgb;
  for (const std::string& out : outputs) {
    const std::string ext = lower_extension(out);
    if (ext == ".tfilm") {
      write_file_atomic(out, encode_film(part));
      continue;
    }
    if (rgb.empty()) rgb = part.film.resolve();
    try {
      if (ext == ".exr")
        tessera::write_exr(out, rgb, part.width, part.height, part.exr_half);
      else
        tessera::write_png(out, rgb, part.width, part.height, part.display);
    } catch (const std::exception& e) {
      retry(e.what());
    }
  }
}

// Usage errors (an unknown format) first, then whether every output can be written: all before any work.
void check_outputs(const std::vector<std::string>& outputs) {
  for (const std::string& out : outputs) {
    const std::string ext = lower_extension(out);
    if (ext != ".png" && ext != ".exr" && ext != ".tfilm")
      throw std::invalid_argument(out + ": unknown output format (use .png, .exr or .tfilm)");
  }
  for (const std::string& out : outputs) check_writable(out);
}

int cmd_render(int argc, char** argv) {
  std::string input;
  std::vector<std::string> outputs;
  json overrides = json::object();
  int threads = 0;
  bool quiet = !isatty(2);
  std::optional<std::pair<long long, long long>> samples;
  std::optional<std::vector<long long>> region;
  std::optional<std::string> variant;
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
    if (a == "-o" || a == "--output")
      outputs.push_back(value());
    else if (a == "--spp")
      overrides["spp"] = parse_integer(a, value());
    else if (a == "--samples") {
      auto v = parse_list(a, value(), ':', 2);
      if (v[0] < 0 || v[1] < 1 || v[0] + v[1] > (1ll << 32) - 1)
        throw std::invalid_argument("--samples START:COUNT needs START >= 0 and COUNT >= 1");
      samples = {v[0], v[1]};
    } else if (a == "--region") {
      region = parse_list(a, value(), ',', 4);
    } else if (a == "--width")
      overrides["width"] = parse_integer(a, value());
    else if (a == "--height")
      overrides["height"] = parse_integer(a, value());
    else if (a == "--time-limit")
      overrides["time_limit_s"] = parse_number(a, value());
    else if (a == "--threads")
      threads = static_cast<int>(parse_integer(a, value()));
    else if (a == "--integrator")
      overrides["integrator"] = value();
    else if (a == "--estimator")
      overrides["estimator"] = value();
    else if (a == "--seed")
      overrides["seed"] = parse_integer(a, value());
    else if (a == "--max-depth")
      overrides["max_depth"] = parse_integer(a, value());
    else if (a == "--variant")
      variant = value();
    else if (a == "-q" || a == "--quiet")
      quiet = true;
    else if (!a.empty() && a[0] == '-')
      unknown_option(a,
                     {"--output", "--spp", "--samples", "--region", "--width", "--height", "--time-limit", "--threads",
                      "--integrator", "--estimator", "--seed", "--max-depth", "--variant", "--quiet", "--help"});
    else if (input.empty())
      input = a;
    else
      throw std::invalid_argument("more than one input file");
  }
  if (input.empty()) throw std::invalid_argument("render needs a job file (tessera render -h)");
  if (outputs.empty()) throw std::invalid_argument("render needs at least one -o OUTPUT (tessera render -h)");
  if (samples && overrides.contains("spp")) throw std::invalid_argument("--samples and --spp exclude each other");
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
      const json& spp = doc["render"].value("spp", json());
      job_spp = std::max<uint64_t>(spp.is_number_unsigned() ? spp.get<uint64_t>() : tessera::kDefaultSpp,
                                   static_cast<uint64_t>(samples->first) + samples->second);
      doc["render"]["spp"] = samples->first + samples->second;
    }
    if (variant && doc.contains("scene") && doc["scene"].is_object()) doc["scene"]["gltf_variant"] = *variant;
  }

  // The daemon's own check, with its messages: the contract's schema (an unknown property such as "albdo" is
  // refused, not rendered with the default), then the renderer's checks in load_job.
  // Asset references name files here, not asset ids: judged as the daemon judges them once a multipart submission
  // has stored their files (whether the file opens is load_job's to say).
  json checked = doc;
  for (std::string_view p : tessera::proto::kAssetRefPointers) {
    const json::json_pointer pointer{std::string(p)};
    if (checked.is_object() && checked.contains(pointer) && checked[pointer].is_string())
      checked[pointer] = std::string(64, '0');
  }
  if (const auto errors = tessera::proto::contract_schemas().validate_all(checked, "job.schema.json");
      !errors.empty()) {
    std::string message;
    for (const tessera::proto::SchemaError& e : errors)
      message += (message.empty() ? "" : "\ntessera: ") + where(e.pointer) + e.message;
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
  tessera::RenderSession session(job.scene, job.settings, pool);
  tessera::StopReason reason = session.run([&](const tessera::RenderProgress& p, const tessera::Film&) {
    if (!quiet) progress_bar(p);
  });
  const tessera::RenderProgress& p = session.progress();
  if (!quiet) std::fprintf(stderr, "\n");
  std::fprintf(stderr,
               "tessera: %dx%d, %u spp in %.2fs (load+BVH %.2fs, %zu triangles), %.3g samples/s, %.3g rays/s, "
               "%d threads, stopped by %s\n",
               job.settings.width, job.settings.height, p.samples_done, p.elapsed_s, load_s,
               job.scene->triangle_count(), p.samples_per_s,
               p.elapsed_s > 0 ? static_cast<double>(p.rays.total()) / p.elapsed_s : 0.0, pool.size(),
               tessera::stop_reason_name(reason));

  PartialFilm part;
  part.width = job.settings.width;
  part.height = job.settings.height;
  part.first_sample = job.settings.first_sample;
  part.sample_count = session.film().samples();
  part.region = session.settings().region;
  if (part.region.width <= 0 || part.region.height <= 0) part.region = {0, 0, part.width, part.height};
  part.exr_half = job.settings.exr_half;
  part.display = job.settings.display;
  part.fingerprint = fingerprint(doc, job.settings, options.scene.asset_root);
  part.film = session.film();
  write_outputs(outputs, part);
  return kExitOk;
}

// ---------------------------------------------------------------------------------------------------------------
// merge

int cmd_merge(int argc, char** argv) {
  std::vector<std::string> inputs, outputs;
  for (int i = 0; i < argc; ++i) {
    std::string a = argv[i];
    if (a == "-h" || a == "--help") {
      std::fputs(kMergeUsage, stdout);
      return kExitOk;
    }
    if (a == "-o" || a == "--output") {
      if (i + 1 >= argc) throw std::invalid_argument(a + " needs a value");
      outputs.push_back(argv[++i]);
    } else if (!a.empty() && a[0] == '-') {
      unknown_option(a, {"--output", "--help"});
    } else {
      inputs.push_back(a);
    }
  }
  if (inputs.empty()) throw std::invalid_argument("merge needs partial films (tessera merge -h)");
  if (outputs.empty()) throw std::invalid_argument("merge needs at least one -o OUTPUT (tessera merge -h)");
  check_outputs(outputs);

  std::vector<PartialFilm> parts;
  for (const std::string& path : inputs) parts.push_back(decode_film(path));
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

  PartialFilm merged;
  merged.width = first.width;
  merged.height = first.height;
  merged.first_sample = lo[0];
  merged.sample_count = hi[0] - lo[0];
  merged.region = {0, 0, first.width, first.height};
  merged.exr_half = first.exr_half;
  merged.display = first.display;
  merged.fingerprint = first.fingerprint;
  merged.film = tessera::Film(first.width, first.height);
  for (const PartialFilm& p : parts) merged.film.merge(p.film);  // integer sums: exact in any order
  // Film::merge counts every part's samples; parts of different regions share a sample range.
  merged.film.set_samples(merged.sample_count);
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
