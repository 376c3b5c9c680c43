// tessera: the command-line tool. `tessera render JOB.json -o out.png -o out.exr` renders locally, no daemon.
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iostream>
#include <string>
#include <vector>

#include "renderer/image_io.h"
#include "renderer/job.h"
#include "renderer/scene_error.h"

namespace {

using nlohmann::json;

// Exit codes: render farm managers tell "try again" from "this job can never work".
constexpr int kExitOk = 0;
constexpr int kExitFatal = 1;  // bad input: the same command will fail again
constexpr int kExitUsage = 2;
constexpr int kExitRetry = 75;  // EX_TEMPFAIL: a transient failure (I/O, resources)

int usage(std::FILE* to) {
  std::fprintf(to,
               "usage: tessera render JOB.json -o OUT.png|OUT.exr [-o ...] [options]\n"
               "\n"
               "Renders a job document (or a bare scene document) locally, without a daemon.\n"
               "\n"
               "options:\n"
               "  -o, --output FILE      write the image; the extension picks the format (.png, .exr)\n"
               "  --spp N                samples per pixel (overrides render.spp)\n"
               "  --width N, --height N  resolution (override render.width/height)\n"
               "  --time-limit S         stop after the pass that crosses S seconds\n"
               "  --threads N            render threads (default: all hardware threads)\n"
               "  --estimator NAME       mis | area | hemisphere\n"
               "  --seed N               random seed\n"
               "  --max-depth N          maximum bounces\n"
               "  -q, --quiet            no progress bar\n"
               "\n"
               "exit codes: 0 done, 1 bad input (fatal), 2 usage, 75 transient failure (retry)\n");
  return to == stdout ? kExitOk : kExitUsage;
}

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

int cmd_render(int argc, char** argv) {
  std::string input;
  std::vector<std::string> outputs;
  json overrides = json::object();
  int threads = 0;
  bool quiet = !isatty(2);
  for (int i = 0; i < argc; ++i) {
    std::string a = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) throw std::invalid_argument(a + " needs a value");
      return argv[++i];
    };
    auto integer = [&](const std::string& v) -> long long {
      size_t pos = 0;
      long long n = std::stoll(v, &pos);
      if (pos != v.size()) throw std::invalid_argument(a + " needs an integer");
      return n;
    };
    if (a == "-h" || a == "--help") return usage(stdout);
    if (a == "-o" || a == "--output") outputs.push_back(value());
    else if (a == "--spp") overrides["spp"] = integer(value());
    else if (a == "--width") overrides["width"] = integer(value());
    else if (a == "--height") overrides["height"] = integer(value());
    else if (a == "--time-limit") overrides["time_limit_s"] = std::stod(value());
    else if (a == "--threads") threads = static_cast<int>(integer(value()));
    else if (a == "--estimator") overrides["estimator"] = value();
    else if (a == "--seed") overrides["seed"] = integer(value());
    else if (a == "--max-depth") overrides["max_depth"] = integer(value());
    else if (a == "-q" || a == "--quiet") quiet = true;
    else if (!a.empty() && a[0] == '-') throw std::invalid_argument("unknown option " + a);
    else if (input.empty()) input = a;
    else throw std::invalid_argument("more than one input file");
  }
  if (input.empty() || outputs.empty()) return usage(stderr);

  std::ifstream in(input);
  if (!in) {
    std::fprintf(stderr, "tessera: cannot open %s: %s\n", input.c_str(), std::strerror(errno));
    return kExitFatal;
  }
  json doc;
  try {
    doc = json::parse(in);
  } catch (const json::parse_error& e) {
    std::fprintf(stderr, "tessera: %s is not valid JSON: %s\n", input.c_str(), e.what());
    return kExitFatal;
  }
  // A bare scene document is wrapped into a job.
  if (doc.is_object() && !doc.contains("kind") && doc.contains("objects")) doc = json{{"kind", "scene"}, {"scene", doc}};
  if (doc.is_object()) {
    if (!doc.contains("render")) doc["render"] = json::object();
    if (doc["render"].is_object()) doc["render"].update(overrides);
  }

  tessera::JobLoadOptions options;
  options.scene.asset_root = std::filesystem::path(input).parent_path();
  tessera::RenderJob job;
  auto t0 = std::chrono::steady_clock::now();
  try {
    job = tessera::load_job(doc, options);
  } catch (const tessera::SceneError& e) {
    std::fprintf(stderr, "tessera: %s: at %s: %s\n", input.c_str(), e.pointer().empty() ? "/" : e.pointer().c_str(),
                 e.what());
    return kExitFatal;
  }
  double load_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();

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
  std::vector<float> rgb = session.film().resolve();
  for (const std::string& out : outputs) {
    try {
      std::string ext = std::filesystem::path(out).extension().string();
      for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
      if (ext == ".exr") {
        tessera::write_exr(out, rgb, job.settings.width, job.settings.height, job.settings.exr_half);
      } else if (ext == ".png") {
        tessera::write_png(out, rgb, job.settings.width, job.settings.height, job.settings.display);
      } else {
        std::fprintf(stderr, "tessera: %s: unknown output format (use .png or .exr)\n", out.c_str());
        return kExitFatal;
      }
    } catch (const std::exception& e) {
      std::fprintf(stderr, "tessera: %s\n", e.what());
      return kExitRetry;
    }
  }
  return kExitOk;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) return usage(stderr);
  std::string cmd = argv[1];
  try {
    if (cmd == "render") return cmd_render(argc - 2, argv + 2);
    if (cmd == "-h" || cmd == "--help" || cmd == "help") return usage(stdout);
    std::fprintf(stderr, "tessera: unknown command '%s'\n", cmd.c_str());
    return usage(stderr);
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
