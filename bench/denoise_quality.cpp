// tessera-denoise-bench: the denoiser's quality and time (renderer/denoise.h). A job is rendered once at REF_SPP as the
// reference, then at each of the sample counts given, and each render's relative MSE against the reference is
// printed for the image as rendered ("noisy") and denoised, with the denoiser's wall time; last, the denoiser alone
// is timed on a 1920 x 1080 render of the same job (16 spp), the median of RUNS runs.
//
// Relative MSE as Rousselle, Knaus and Zwicker ("Adaptive Sampling and Reconstruction using Greedy Error
// Minimization", SIGGRAPH Asia 2011) define it: the mean over pixels and channels of (x - ref)^2 / (ref^2 + 0.01).
//
//   tessera-denoise-bench JOB.json [--size W H] [--ref-spp N] [--spp N,N,...] [--runs N] [--threads N]
//                         [--window R] [--patch F] [--strength K] [--no-time]
//
// --window, --patch and --strength set the denoiser's parameters (RegressionDenoiserOptions); --no-time leaves out
// the timing at 1920 x 1080.
//
// Run it from the repository root.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "renderer/denoise.h"
#include "renderer/job.h"
#include "renderer/output.h"
#include "renderer/session.h"

using namespace tessera;
using nlohmann::json;

namespace {

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

double relative_mse(const std::vector<float>& x, const std::vector<float>& ref) {
  double sum = 0;
  for (size_t i = 0; i < x.size(); ++i) {
    const double d = static_cast<double>(x[i]) - ref[i];
    sum += d * d / (static_cast<double>(ref[i]) * ref[i] + 0.01);
  }
  return sum / static_cast<double>(x.size());
}

struct Bench {
  json job;
  std::string asset_root;
  int threads = 0;

  // The film of the job at w x h and spp, with the denoiser's features.
  Film render(int w, int h, uint32_t spp, uint64_t seed, RenderSettings* out) const {
    json j = job;
    j["render"]["width"] = w;
    j["render"]["height"] = h;
    j["render"]["spp"] = spp;
    j["render"]["seed"] = seed;
    j["render"]["denoise"] = "regression";
    JobLoadOptions opts;
    opts.scene.asset_root = asset_root;
    RenderJob loaded = load_job(j, opts);
    ThreadPool pool(threads);
    RenderSession session(loaded.scene, loaded.settings, pool);
    session.run();
    *out = loaded.settings;
    return session.take_film();
  }
  // The resolved image with the denoiser's features, not yet denoised.
  static Image resolve(const Film& film, const RenderSettings& s) { return resolve_image(film, film_aovs(s)); }
};

}  // namespace

int main(int argc, char** argv) try {
  if (argc < 2) {
    std::fprintf(stderr,
                 "usage: tessera-denoise-bench JOB.json [--size W H] [--ref-spp N] [--spp N,N,...] "
                 "[--runs N] [--threads N]\n");
    return 2;
  }
  const std::string path = argv[1];
  int w = 256, h = 256, runs = 3;
  uint32_t ref_spp = 16384;
  std::vector<uint32_t> spps = {16, 64, 256, 1024};
  Bench bench;
  RegressionDenoiserOptions options;
  bool time_big = true;
  for (int i = 2; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) throw std::runtime_error(a + " needs a value");
      return argv[++i];
    };
    if (a == "--size") {
      w = std::stoi(next());
      h = std::stoi(next());
    } else if (a == "--ref-spp") {
      ref_spp = static_cast<uint32_t>(std::stoul(next()));
    } else if (a == "--spp") {
      spps.clear();
      std::stringstream list(next());
      for (std::string item; std::getline(list, item, ',');) spps.push_back(static_cast<uint32_t>(std::stoul(item)));
    } else if (a == "--runs") {
      runs = std::stoi(next());
    } else if (a == "--threads") {
      bench.threads = std::stoi(next());
    } else if (a == "--window") {
      options.window_radius = std::stoi(next());
    } else if (a == "--patch") {
      options.patch_radius = std::stoi(next());
    } else if (a == "--strength") {
      options.strength = std::stof(next());
    } else if (a == "--no-time") {
      time_big = false;
    } else {
      throw std::runtime_error("unknown option " + a);
    }
  }
  std::ifstream in(path);
  if (!in) throw std::runtime_error("cannot open " + path);
  bench.job = json::parse(in);
  bench.asset_root = std::filesystem::path(path).parent_path().string();

  RenderSettings s;
  auto t0 = std::chrono::steady_clock::now();
  const std::vector<float> reference = bench.render(w, h, ref_spp, 1000, &s).resolve();
  std::printf("%s at %dx%d: reference %u spp (%.1f s)\n", path.c_str(), w, h, ref_spp, seconds_since(t0));
  std::printf("%6s %12s %12s %10s %10s\n", "spp", "noisy_relmse", "denoised", "ratio", "denoise_s");
  options.threads = static_cast<unsigned>(bench.threads);
  const RegressionDenoiser denoiser(options);
  for (uint32_t spp : spps) {
    const Film film = bench.render(w, h, spp, 1, &s);
    Image image = Bench::resolve(film, s);
    const double noisy = relative_mse(image.beauty().pixels, reference);
    t0 = std::chrono::steady_clock::now();
    denoiser.apply(image);
    const double took = seconds_since(t0);
    const double denoised = relative_mse(image.beauty().pixels, reference);
    std::printf("%6u %12.4e %12.4e %10.2f %10.3f\n", spp, noisy, denoised, noisy / denoised, took);
  }

  if (!time_big) return 0;
  const Film big = bench.render(1920, 1080, 16, 1, &s);
  const Image resolved = Bench::resolve(big, s);
  std::vector<double> times;
  for (int r = 0; r < runs; ++r) {
    Image image = resolved;
    t0 = std::chrono::steady_clock::now();
    denoiser.apply(image);
    times.push_back(seconds_since(t0));
  }
  std::sort(times.begin(), times.end());
  std::printf("denoiser at 1920x1080: %.2f s (median of %d runs, %u hardware threads)\n", times[times.size() / 2], runs,
              std::thread::hardware_concurrency());
  return 0;
} catch (const std::exception& e) {
  std::fprintf(stderr, "tessera-denoise-bench: %s\n", e.what());
  return 1;
}
