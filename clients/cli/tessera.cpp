// tessera: the command-line tool.
//   tessera render JOB.json|SCENE.glb -o out.png [-o out.exr] [-o part.tfilm] [--samples START:COUNT] ...
//   tessera merge part1.tfilm part2.tfilm ... -o out.exr|out.png|out.tfilm
//   tessera submit|watch|fetch|list|cancel ...   against a tesserad (--url, --token)
//
// Exit codes (render farm managers tell "try again" from "this can never work"): 0 done, 1 fatal (bad input, a
// refused job, a failed render), 2 usage, 75 retry (transient: I/O, network, server 5xx, 429, 503).
#include <httplib.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "renderer/image_io.h"
#include "renderer/job.h"
#include "renderer/scene_error.h"

namespace {

using nlohmann::json;

constexpr int kExitOk = 0;
constexpr int kExitFatal = 1;  // bad input: the same command will fail again
constexpr int kExitUsage = 2;
constexpr int kExitRetry = 75;  // EX_TEMPFAIL: a transient failure (I/O, resources, network, server overload)

// A failure with the exit code it deserves; caught in main().
struct Failure : std::runtime_error {
  int code;
  Failure(int c, const std::string& what) : std::runtime_error(what), code(c) {}
};
[[noreturn]] void fatal(const std::string& what) { throw Failure(kExitFatal, what); }
[[noreturn]] void retry(const std::string& what) { throw Failure(kExitRetry, what); }

const char* kUsage =
    "usage: tessera COMMAND [options]\n"
    "\n"
    "local (no daemon):\n"
    "  render JOB.json|SCENE.glb|SCENE.gltf -o OUT [-o OUT...]   render a job or a glTF asset; OUT is .png, .exr\n"
    "                                       or .tfilm (a partial film for merge)\n"
    "  merge PART.tfilm... -o OUT           combine sample ranges / regions into one image (bit-exact)\n"
    "against a daemon (--url URL or TESSERA_URL, default http://127.0.0.1:8080; --token T or TESSERA_TOKEN):\n"
    "  submit JOB.json|SCENE.glb|SCENE.gltf [FILE...]   submit a job (multipart with files); prints its id\n"
    "  watch ID                             follow a job until it ends (events, or polling)\n"
    "  fetch ID [-d DIR] [-o FILE...]       download a finished job's results\n"
    "  list [--state S] [--limit N] [--json]\n"
    "  cancel ID\n"
    "\n"
    "`tessera COMMAND -h` describes a command.\n"
    "exit codes: 0 done, 1 fatal (bad input, refused or failed job), 2 usage, 75 transient failure (retry)\n";

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
    "                         parts merge into exactly the image of one render of all samples\n"
    "  --region X,Y,W,H       render only this pixel rectangle (the image keeps its full size)\n"
    "  --width N, --height N  resolution (override render.width/height)\n"
    "  --time-limit S         stop after the pass that crosses S seconds\n"
    "  --threads N            render threads (default: all hardware threads)\n"
    "  --estimator NAME       mis | area | hemisphere\n"
    "  --seed N               random seed\n"
    "  --max-depth N          maximum bounces\n"
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

long long parse_integer(const std::string& option, const std::string& v) {
  size_t pos = 0;
  long long n = 0;
  try {
    n = std::stoll(v, &pos);
  } catch (const std::exception&) {
    pos = 0;
  }
  if (pos != v.size() || v.empty()) throw std::invalid_argument(option + " needs an integer, not \"" + v + "\"");
  return n;
}

double parse_number(const std::string& option, const std::string& v) {
  size_t pos = 0;
  double d = 0;
  try {
    d = std::stod(v, &pos);
  } catch (const std::exception&) {
    pos = 0;
  }
  if (pos != v.size() || v.empty() || !std::isfinite(d))
    throw std::invalid_argument(option + " needs a number, not \"" + v + "\"");
  return d;
}

std::vector<long long> parse_list(const std::string& option, const std::string& v, char sep, size_t count) {
  std::vector<long long> out;
  std::stringstream ss(v);
  std::string item;
  while (std::getline(ss, item, sep)) out.push_back(parse_integer(option, item));
  if (out.size() != count)
    throw std::invalid_argument(option + " needs " + std::to_string(count) + " integers separated by '" +
                                std::string(1, sep) + "', not \"" + v + "\"");
  return out;
}

std::string lower_extension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return ext;
}

std::string read_file(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) fatal("cannot open " + path.string() + ": " + std::strerror(errno));
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

// Writes through a temporary file renamed into place: a reader never sees half a file.
void write_file_atomic(const std::string& path, const std::string& bytes) {
  const std::string tmp = path + ".part";
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) retry("cannot write " + tmp + ": " + std::strerror(errno));
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    if (!out) retry("cannot write " + tmp + ": " + std::strerror(errno));
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) retry("cannot rename " + tmp + " to " + path + ": " + ec.message());
}

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
      if ((key == "gltf" || key == "map" || key == "texture") && value.is_string()) out->insert(value.get<std::string>());
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
      if (ext == ".exr") tessera::write_exr(out, rgb, part.width, part.height, part.exr_half);
      else tessera::write_png(out, rgb, part.width, part.height, part.display);
    } catch (const std::exception& e) {
      retry(e.what());
    }
  }
}

void check_output_names(const std::vector<std::string>& outputs) {
  for (const std::string& out : outputs) {
    const std::string ext = lower_extension(out);
    if (ext != ".png" && ext != ".exr" && ext != ".tfilm")
      throw std::invalid_argument(out + ": unknown output format (use .png, .exr or .tfilm)");
  }
}

int cmd_render(int argc, char** argv) {
  std::string input;
  std::vector<std::string> outputs;
  json overrides = json::object();
  int threads = 0;
  bool quiet = !isatty(2);
  std::optional<std::pair<long long, long long>> samples;
  std::optional<std::vector<long long>> region;
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
    if (a == "-o" || a == "--output") outputs.push_back(value());
    else if (a == "--spp") overrides["spp"] = parse_integer(a, value());
    else if (a == "--samples") {
      auto v = parse_list(a, value(), ':', 2);
      if (v[0] < 0 || v[1] < 1 || v[0] + v[1] > (1ll << 32) - 1)
        throw std::invalid_argument("--samples START:COUNT needs START >= 0 and COUNT >= 1");
      samples = {v[0], v[1]};
    } else if (a == "--region") {
      region = parse_list(a, value(), ',', 4);
    } else if (a == "--width") overrides["width"] = parse_integer(a, value());
    else if (a == "--height") overrides["height"] = parse_integer(a, value());
    else if (a == "--time-limit") overrides["time_limit_s"] = parse_number(a, value());
    else if (a == "--threads") threads = static_cast<int>(parse_integer(a, value()));
    else if (a == "--estimator") overrides["estimator"] = value();
    else if (a == "--seed") overrides["seed"] = parse_integer(a, value());
    else if (a == "--max-depth") overrides["max_depth"] = parse_integer(a, value());
    else if (a == "-q" || a == "--quiet") quiet = true;
    else if (!a.empty() && a[0] == '-') throw std::invalid_argument("unknown option " + a);
    else if (input.empty()) input = a;
    else throw std::invalid_argument("more than one input file");
  }
  if (input.empty()) throw std::invalid_argument("render needs a job file (tessera render -h)");
  if (outputs.empty()) throw std::invalid_argument("render needs at least one -o OUTPUT (tessera render -h)");
  check_output_names(outputs);
  if (samples && overrides.contains("spp")) throw std::invalid_argument("--samples and --spp exclude each other");

  std::ifstream in(input);
  if (!in) fatal("cannot open " + input + ": " + std::strerror(errno));
  json doc;
  std::string extension = std::filesystem::path(input).extension().string();
  std::transform(extension.begin(), extension.end(), extension.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  if (extension == ".glb" || extension == ".gltf") {
    // A glTF asset renders as the scene of a job that names it (its camera, lights and materials; the files it
    // refers to are read from beside it).
    doc = json{{"kind", "scene"}, {"scene", {{"gltf", std::filesystem::path(input).filename().string()}}}};
  } else {
    try {
      doc = json::parse(in);
    } catch (const json::parse_error& e) {
      fatal(input + " is not valid JSON: " + e.what());
    }
  }
  // A bare scene document is wrapped into a job.
  if (doc.is_object() && !doc.contains("kind") && doc.contains("objects")) doc = json{{"kind", "scene"}, {"scene", doc}};
  if (doc.is_object()) {
    if (!doc.contains("render")) doc["render"] = json::object();
    if (doc["render"].is_object()) doc["render"].update(overrides);
    // A sample range is a part of the job's budget: the whole of it must be there for the settings to load.
    if (samples && doc["render"].is_object()) doc["render"]["spp"] = samples->first + samples->second;
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
    fatal(input + ": at " + (e.pointer().empty() ? std::string("/") : e.pointer()) + ": " + e.what());
  }
  double load_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();

  if (samples) {
    job.settings.first_sample = static_cast<uint32_t>(samples->first);
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
      throw std::invalid_argument("unknown option " + a);
    } else {
      inputs.push_back(a);
    }
  }
  if (inputs.empty()) throw std::invalid_argument("merge needs partial films (tessera merge -h)");
  if (outputs.empty()) throw std::invalid_argument("merge needs at least one -o OUTPUT (tessera merge -h)");
  check_output_names(outputs);

  std::vector<PartialFilm> parts;
  for (const std::string& path : inputs) parts.push_back(decode_film(path));
  const PartialFilm& first = parts.front();
  auto describe = [](const PartialFilm& p) {
    const auto& r = p.region;
    return p.path + " (samples " + std::to_string(p.first_sample) + ":" + std::to_string(p.sample_count) +
           ", region " + std::to_string(r.x) + "," + std::to_string(r.y) + "," + std::to_string(r.width) + "," +
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
      const bool samples_meet = a.first_sample < b.first_sample + b.sample_count &&
                                b.first_sample < a.first_sample + a.sample_count;
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
  std::fprintf(stderr, "tessera: merged %zu parts: %dx%d, samples %u..%u\n", parts.size(), merged.width,
               merged.height, merged.first_sample, merged.first_sample + merged.sample_count);
  return kExitOk;
}

// ---------------------------------------------------------------------------------------------------------------
// The daemon's API

struct Remote {
  std::string url;
  std::string token;

  std::unique_ptr<httplib::Client> client(int read_timeout_s = 60) const {
    auto c = std::make_unique<httplib::Client>(url);
    if (!c->is_valid()) throw std::invalid_argument("bad --url " + url);
    c->set_connection_timeout(10, 0);
    c->set_read_timeout(read_timeout_s, 0);
    c->set_write_timeout(60, 0);
    if (!token.empty()) c->set_bearer_token_auth(token);
    return c;
  }
};

// Remote options shared by every daemon command; removes them from args.
Remote remote_options(std::vector<std::string>* args) {
  Remote r;
  const char* env_url = std::getenv("TESSERA_URL");
  const char* env_token = std::getenv("TESSERA_TOKEN");
  r.url = env_url && *env_url ? env_url : "http://127.0.0.1:8080";
  r.token = env_token ? env_token : "";
  std::vector<std::string> rest;
  for (size_t i = 0; i < args->size(); ++i) {
    const std::string& a = (*args)[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= args->size()) throw std::invalid_argument(a + " needs a value");
      return (*args)[++i];
    };
    if (a == "--url") r.url = value();
    else if (a == "--token") r.token = value();
    else rest.push_back(a);
  }
  while (!r.url.empty() && r.url.back() == '/') r.url.pop_back();
  if (r.url.rfind("http://", 0) != 0 && r.url.rfind("https://", 0) != 0)
    throw std::invalid_argument("--url must start with http:// or https://, not \"" + r.url + "\"");
  *args = std::move(rest);
  return r;
}

// Turns a failed exchange into a Failure: no answer or 5xx/429/503 is transient (75), any other 4xx fatal (1).
[[noreturn]] void http_failure(const Remote& remote, const httplib::Result& res, const std::string& what) {
  if (!res) retry(what + ": cannot reach " + remote.url + " (" + httplib::to_string(res.error()) + ")");
  std::string message = what + ": HTTP " + std::to_string(res->status);
  const json problem = json::parse(res->body, nullptr, false);
  if (problem.is_object()) {
    if (problem.contains("title") && problem["title"].is_string()) message += " " + problem["title"].get<std::string>();
    if (problem.contains("detail") && problem["detail"].is_string())
      message += ": " + problem["detail"].get<std::string>();
    if (problem.contains("pointer") && problem["pointer"].is_string())
      message += " (at " + (problem["pointer"].get<std::string>().empty() ? "/" : problem["pointer"].get<std::string>()) + ")";
  } else if (!res->body.empty()) {
    message += ": " + res->body.substr(0, 300);
  }
  if (res->status == 401) message += " (give a token with --token or TESSERA_TOKEN)";
  if (res->status >= 500 || res->status == 429 || res->status == 408) retry(message);
  fatal(message);
}

json expect_json(const Remote& remote, const httplib::Result& res, const std::string& what) {
  if (!res || res->status < 200 || res->status >= 300) http_failure(remote, res, what);
  json j = json::parse(res->body, nullptr, false);
  if (j.is_discarded()) retry(what + ": the daemon's answer is not JSON");
  return j;
}

std::string progress_line(const json& job) {
  const json& p = job.value("progress", json::object());
  char buf[256];
  const double frac = p.value("fraction", 0.0);
  std::string eta = "?";
  if (p.contains("eta_s") && p["eta_s"].is_number()) {
    char e[32];
    std::snprintf(e, sizeof e, "%.1fs", p["eta_s"].get<double>());
    eta = e;
  }
  std::snprintf(buf, sizeof buf, "%-9s %3.0f%%  %d/%d spp  pass %d  %.1fs  eta %s  %.3g samples/s",
                job.value("state", "?").c_str(), frac * 100, p.value("samples_done", 0), p.value("samples_total", 0),
                p.value("passes", 0), p.value("elapsed_s", 0.0), eta.c_str(), p.value("samples_per_s", 0.0));
  std::string line = buf;
  if (job.contains("stop_reason") && job["stop_reason"].is_string())
    line += "  stopped by " + job["stop_reason"].get<std::string>();
  if (job.contains("error") && job["error"].is_string()) line += "  error: " + job["error"].get<std::string>();
  return line;
}

std::string url_component(const std::string& s) {
  std::string out;
  for (unsigned char c : s) {
    if (std::isalnum(c) || c == '-' || c == '_' || c == '.' || c == ',') {
      out += static_cast<char>(c);
    } else {
      char b[4];
      std::snprintf(b, sizeof b, "%%%02X", c);
      out += b;
    }
  }
  return out;
}

bool is_terminal(const std::string& s) { return s == "succeeded" || s == "failed" || s == "cancelled"; }

std::string job_path(const std::string& id) {
  for (char c : id)
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '-' && c != '_')
      throw std::invalid_argument("\"" + id + "\" is not a job id");
  return "/v1/jobs/" + id;
}

void require_args(const std::vector<std::string>& args, size_t lo, size_t hi, const char* usage) {
  for (const std::string& a : args)
    if (a == "-h" || a == "--help") {
      std::fputs(usage, stdout);
      throw Failure(kExitOk, "");
    }
  if (args.size() < lo || args.size() > hi) throw std::invalid_argument(std::string("wrong arguments\n") + usage);
}

const char* kSubmitUsage =
    "usage: tessera submit JOB.json|SCENE.glb|SCENE.gltf [FILE...] [--priority N] [--spp N] [--width N] [--height N]\n"
    "                      [--watch] [--url URL] [--token T]\n"
    "Submits a job and prints its id. With a .glb/.gltf (and the .bin and images a .gltf needs) the job goes as\n"
    "multipart/form-data; a job document whose scene.gltf names a file beside it takes that file along.\n"
    "--watch follows the job until it ends (exit code as for watch).\n";

int cmd_watch_remote(const Remote& remote, const std::string& id, bool quiet);

int cmd_submit(std::vector<std::string> args) {
  Remote remote = remote_options(&args);
  std::vector<std::string> files;
  json overrides = json::object();
  std::optional<long long> priority;
  bool watch = false;
  for (size_t i = 0; i < args.size(); ++i) {
    const std::string& a = args[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= args.size()) throw std::invalid_argument(a + " needs a value");
      return args[++i];
    };
    if (a == "-h" || a == "--help") {
      std::fputs(kSubmitUsage, stdout);
      return kExitOk;
    }
    if (a == "--priority") priority = parse_integer(a, value());
    else if (a == "--spp" || a == "--width" || a == "--height") overrides[a.substr(2)] = parse_integer(a, value());
    else if (a == "--watch") watch = true;
    else if (!a.empty() && a[0] == '-') throw std::invalid_argument("unknown option " + a);
    else files.push_back(a);
  }
  if (files.empty()) throw std::invalid_argument(std::string("submit needs a job or a glTF file\n") + kSubmitUsage);

  json doc;
  std::vector<std::string> attachments;
  const std::string main = files.front();
  const std::string ext = lower_extension(main);
  if (ext == ".glb" || ext == ".gltf") {
    doc = {{"kind", "scene"}, {"scene", {{"gltf", std::filesystem::path(main).filename().string()}}}};
    attachments = files;
  } else {
    const std::string text = main == "-" ? std::string(std::istreambuf_iterator<char>(std::cin), {}) : read_file(main);
    doc = json::parse(text, nullptr, false);
    if (doc.is_discarded() || !doc.is_object()) fatal(main + " is not a JSON object");
    attachments.assign(files.begin() + 1, files.end());
    // A scene that names a glTF file beside the job document takes it along.
    if (attachments.empty() && main != "-" && doc.contains("scene") && doc["scene"].is_object() &&
        doc["scene"].contains("gltf") && doc["scene"]["gltf"].is_string()) {
      const auto asset = std::filesystem::path(main).parent_path() / doc["scene"]["gltf"].get<std::string>();
      std::error_code ec;
      if (std::filesystem::is_regular_file(asset, ec)) attachments.push_back(asset.string());
    }
  }
  if (!overrides.empty()) {
    if (!doc.contains("render") || !doc["render"].is_object()) doc["render"] = json::object();
    doc["render"].update(overrides);
  }
  if (priority) doc["priority"] = *priority;
  // A .gltf names its buffers and images: take those that sit beside it along too.
  for (size_t i = 0; i < attachments.size(); ++i) {
    if (lower_extension(attachments[i]) != ".gltf") continue;
    json g = json::parse(read_file(attachments[i]), nullptr, false);
    if (!g.is_object()) continue;
    for (const char* key : {"buffers", "images"}) {
      for (const json& e : g.value(key, json::array())) {
        if (!e.is_object() || !e.contains("uri") || !e["uri"].is_string()) continue;
        const std::string uri = e["uri"].get<std::string>();
        if (uri.rfind("data:", 0) == 0 || uri.find('/') != std::string::npos) continue;
        const auto file = (std::filesystem::path(attachments[i]).parent_path() / uri).string();
        if (std::find(attachments.begin(), attachments.end(), file) == attachments.end() &&
            std::filesystem::exists(file))
          attachments.push_back(file);
      }
    }
  }

  auto client = remote.client();
  auto post = [&]() -> httplib::Result {
    if (attachments.empty()) return client->Post("/v1/jobs", doc.dump(), "application/json");
    httplib::MultipartFormDataItems items;
    items.push_back({"job", doc.dump(), "job.json", "application/json"});
    for (const std::string& f : attachments) {
      const std::string e = lower_extension(f);
      const std::string type = e == ".glb"    ? "model/gltf-binary"
                               : e == ".gltf" ? "model/gltf+json"
                               : e == ".png"  ? "image/png"
                               : e == ".jpg" || e == ".jpeg" ? "image/jpeg"
                                                             : "application/octet-stream";
      items.push_back({"file", read_file(f), std::filesystem::path(f).filename().string(), type});
    }
    return client->Post("/v1/jobs", items);
  };
  const httplib::Result res = post();
  const json job = expect_json(remote, res, "submit");
  const std::string id = job.value("id", "");
  if (id.empty()) retry("submit: the daemon's answer has no job id");
  std::printf("%s\n", id.c_str());
  std::fflush(stdout);
  if (watch) return cmd_watch_remote(remote, id, false);
  return kExitOk;
}

const char* kWatchUsage =
    "usage: tessera watch ID [--interval S] [-q] [--url URL] [--token T]\n"
    "Follows a job until it ends: the daemon's Server-Sent Events, or polling every S seconds (default 1) when it\n"
    "has none. Exit code: 0 succeeded, 1 failed or cancelled, 75 the daemon could not be reached.\n";

double g_poll_interval_s = 1.0;

int exit_for_state(const json& job) {
  const std::string state = job.value("state", "");
  if (state == "succeeded") return kExitOk;
  if (job.contains("error") && job["error"].is_string())
    std::fprintf(stderr, "tessera: job %s: %s\n", state.c_str(), job["error"].get<std::string>().c_str());
  return kExitFatal;
}

// Follows the events stream. Returns the final job status, or nothing when the daemon has no events endpoint (404)
// or the stream ended early.
std::optional<json> watch_events(const Remote& remote, const std::string& id, bool quiet, bool* no_endpoint) {
  auto client = remote.client(45);  // the daemon sends a keep-alive comment every 15 s
  std::string buffer, event, data;
  std::optional<json> last;
  bool done = false;
  int status = 0;
  uint64_t last_id = 0;
  auto dispatch = [&]() {
    if (event.empty() && data.empty()) return;
    json d = json::parse(data, nullptr, false);
    if (event == "state" && d.is_object()) {
      last = d;
      if (!quiet) std::printf("%s\n", progress_line(d).c_str());
      if (is_terminal(d.value("state", ""))) done = true;
    } else if (event == "progress" && d.is_object() && last) {
      (*last)["progress"] = d.value("progress", json::object());
      if (!quiet) std::printf("%s\n", progress_line(*last).c_str());
    }
    std::fflush(stdout);
    event.clear();
    data.clear();
  };
  for (int attempt = 0; attempt < 5 && !done; ++attempt) {
    httplib::Headers headers = {{"Accept", "text/event-stream"}};
    if (last_id) headers.emplace("Last-Event-ID", std::to_string(last_id));
    auto res = client->Get(
        (job_path(id) + "/events").c_str(), headers,
        [&](const httplib::Response& r) {
          status = r.status;
          return r.status == 200;
        },
        [&](const char* bytes, size_t n) {
          buffer.append(bytes, n);
          size_t pos;
          while ((pos = buffer.find('\n')) != std::string::npos) {
            std::string line = buffer.substr(0, pos);
            buffer.erase(0, pos + 1);
            if (!line.empty() && line.back() == '\r') line.pop_back();
            if (line.empty()) dispatch();
            else if (line.rfind("event:", 0) == 0) event = line.substr(line[6] == ' ' ? 7 : 6);
            else if (line.rfind("data:", 0) == 0) data += (data.empty() ? "" : "\n") + line.substr(line[5] == ' ' ? 6 : 5);
            else if (line.rfind("id:", 0) == 0) last_id = std::strtoull(line.c_str() + 3, nullptr, 10);
            if (done) return false;
          }
          return true;
        });
    if (done) return last;
    if (status == 404 && !last) {
      *no_endpoint = true;  // a daemon without events: poll
      return std::nullopt;
    }
    if (status != 0 && status != 200) {
      // An error answer (401, 404 for an unknown job, 5xx): read its problem with a plain request.
      http_failure(remote, client->Get((job_path(id) + "/events").c_str()), "watch");
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(500));  // dropped: reconnect from last_id
  }
  return last && done ? last : std::nullopt;
}

int cmd_watch_remote(const Remote& remote, const std::string& id, bool quiet) {
  bool no_endpoint = false;
  if (auto final_job = watch_events(remote, id, quiet, &no_endpoint)) return exit_for_state(*final_job);
  auto client = remote.client();
  std::string previous;
  for (;;) {
    const json job = expect_json(remote, client->Get(job_path(id).c_str()), "watch");
    const std::string line = progress_line(job);
    if (!quiet && line != previous) std::printf("%s\n", line.c_str());
    std::fflush(stdout);
    previous = line;
    if (is_terminal(job.value("state", ""))) return exit_for_state(job);
    std::this_thread::sleep_for(std::chrono::duration<double>(g_poll_interval_s));
  }
}

int cmd_watch(std::vector<std::string> args) {
  Remote remote = remote_options(&args);
  bool quiet = false;
  std::vector<std::string> rest;
  for (size_t i = 0; i < args.size(); ++i) {
    if (args[i] == "-q" || args[i] == "--quiet") quiet = true;
    else if (args[i] == "--interval") {
      if (i + 1 >= args.size()) throw std::invalid_argument("--interval needs a value");
      g_poll_interval_s = parse_number("--interval", args[++i]);
      if (g_poll_interval_s <= 0) throw std::invalid_argument("--interval must be positive");
    } else rest.push_back(args[i]);
  }
  require_args(rest, 1, 1, kWatchUsage);
  return cmd_watch_remote(remote, rest[0], quiet);
}

const char* kFetchUsage =
    "usage: tessera fetch ID [-d DIR] [-o FILE.png|FILE.exr ...] [--url URL] [--token T]\n"
    "Downloads a finished job's results: to the -o files, else every output the job has into DIR (default .) as\n"
    "ID.png and ID.exr. Exit code 75 while the job has not finished yet, 1 when it failed or was cancelled.\n";

int cmd_fetch(std::vector<std::string> args) {
  Remote remote = remote_options(&args);
  std::string dir = ".";
  std::vector<std::string> outputs, rest;
  for (size_t i = 0; i < args.size(); ++i) {
    const std::string& a = args[i];
    if ((a == "-d" || a == "--dir" || a == "-o" || a == "--output") && i + 1 >= args.size())
      throw std::invalid_argument(a + " needs a value");
    if (a == "-d" || a == "--dir") dir = args[++i];
    else if (a == "-o" || a == "--output") outputs.push_back(args[++i]);
    else if (a != "-h" && a != "--help" && !a.empty() && a[0] == '-') throw std::invalid_argument("unknown option " + a);
    else rest.push_back(a);
  }
  require_args(rest, 1, 1, kFetchUsage);
  const std::string id = rest[0];
  for (const std::string& o : outputs)
    if (lower_extension(o) != ".png" && lower_extension(o) != ".exr")
      throw std::invalid_argument(o + ": fetch writes .png or .exr files");
  auto client = remote.client();
  const json job = expect_json(remote, client->Get(job_path(id).c_str()), "fetch");
  const std::string state = job.value("state", "");
  if (state != "succeeded") {
    if (is_terminal(state)) fatal("job " + id + " " + state + ": it has no results");
    retry("job " + id + " is " + state + ": results exist once it has succeeded");
  }
  if (outputs.empty()) {
    std::filesystem::create_directories(dir);
    for (const json& o : job.value("outputs", json::array()))
      if (o.is_string()) outputs.push_back((std::filesystem::path(dir) / (id + "." + o.get<std::string>())).string());
  }
  for (const std::string& out : outputs) {
    const std::string ext = lower_extension(out).substr(1);
    auto res = client->Get((job_path(id) + "/result." + ext).c_str());
    if (!res || res->status != 200) http_failure(remote, res, "fetch " + ext);
    write_file_atomic(out, res->body);
    std::printf("%s\n", out.c_str());
  }
  return kExitOk;
}

const char* kListUsage =
    "usage: tessera list [--state S] [--limit N] [--json] [--url URL] [--token T]\n"
    "Lists jobs, newest first: id, state, priority, samples, created.\n";

int cmd_list(std::vector<std::string> args) {
  Remote remote = remote_options(&args);
  std::string query;
  bool as_json = false;
  std::vector<std::string> rest;
  for (size_t i = 0; i < args.size(); ++i) {
    const std::string& a = args[i];
    if ((a == "--state" || a == "--limit") && i + 1 >= args.size()) throw std::invalid_argument(a + " needs a value");
    if (a == "--state") query += std::string(query.empty() ? "?" : "&") + "state=" + url_component(args[++i]);
    else if (a == "--limit") query += std::string(query.empty() ? "?" : "&") + "limit=" + std::to_string(parse_integer(a, args[++i]));
    else if (a == "--json") as_json = true;
    else rest.push_back(a);
  }
  require_args(rest, 0, 0, kListUsage);
  auto client = remote.client();
  const json list = expect_json(remote, client->Get(("/v1/jobs" + query).c_str()), "list");
  if (as_json) {
    std::printf("%s\n", list.dump(2).c_str());
    return kExitOk;
  }
  for (const json& j : list.value("jobs", json::array())) {
    const json& p = j.value("progress", json::object());
    std::printf("%s  %-9s  %4d  %6d/%-6d spp  %s\n", j.value("id", "").c_str(), j.value("state", "").c_str(),
                j.value("priority", 0), p.value("samples_done", 0), p.value("samples_total", 0),
                j.value("created_at", "").c_str());
  }
  return kExitOk;
}

const char* kCancelUsage =
    "usage: tessera cancel ID [--url URL] [--token T]\n"
    "Cancels a queued or running job and prints its state (1 when it had already ended).\n";

int cmd_cancel(std::vector<std::string> args) {
  Remote remote = remote_options(&args);
  require_args(args, 1, 1, kCancelUsage);
  auto client = remote.client();
  const json job = expect_json(remote, client->Post((job_path(args[0]) + "/cancel").c_str()), "cancel");
  std::printf("%s\n", job.value("state", "").c_str());
  return kExitOk;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fputs(kUsage, stderr);
    return kExitUsage;
  }
  const std::string cmd = argv[1];
  std::vector<std::string> args(argv + 2, argv + argc);
  try {
    if (cmd == "render") return cmd_render(argc - 2, argv + 2);
    if (cmd == "merge") return cmd_merge(argc - 2, argv + 2);
    if (cmd == "submit") return cmd_submit(args);
    if (cmd == "watch") return cmd_watch(args);
    if (cmd == "fetch") return cmd_fetch(args);
    if (cmd == "list") return cmd_list(args);
    if (cmd == "cancel") return cmd_cancel(args);
    if (cmd == "-h" || cmd == "--help" || cmd == "help") {
      std::fputs(kUsage, stdout);
      return kExitOk;
    }
    std::fprintf(stderr, "tessera: unknown command '%s'\n\n%s", cmd.c_str(), kUsage);
    return kExitUsage;
  } catch (const Failure& f) {
    if (f.what()[0]) std::fprintf(stderr, "tessera: %s\n", f.what());
    return f.code;
  } catch (const std::invalid_argument& e) {
    std::fprintf(stderr, "tessera: %s\n", e.what());
    return kExitUsage;
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "tessera: out of memory\n");
    return kExitRetry;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "tessera: %s\n", e.what());
    return kExitRetry;
  }
}
