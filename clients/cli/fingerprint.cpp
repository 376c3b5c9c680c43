#include "clients/cli/fingerprint.h"

#include <set>
#include <string>
#include <vector>

#include "clients/cli/cli_common.h"
#include "renderer/byte_fields.h"

namespace tessera::cli {

using nlohmann::json;

namespace {

// The same over a file's bytes, read a megabyte at a time (an environment map can be hundreds of megabytes).
uint64_t fnv1a_file(uint64_t h, const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) fatal("cannot open " + path.string() + ": " + std::strerror(errno));
  std::vector<char> chunk(1 << 20);
  while (in) {
    in.read(chunk.data(), static_cast<std::streamsize>(chunk.size()));
    h = fnv1a64(std::string_view(chunk.data(), static_cast<size_t>(in.gcount())), h);
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

}  // namespace

uint64_t film_fingerprint(const json& doc, const RenderSettings& s, const std::filesystem::path& asset_root) {
  json scene = doc;
  for (const char* key : {"render", "outputs", "priority"}) scene.erase(key);
  // The settings the film's sums depend on; the others keep their defaults, so that every part of one render agrees.
  RenderSettings film;
  film.width = s.width;
  film.height = s.height;
  film.seed = s.seed;
  film.sampler = s.sampler;
  film.integrator = s.integrator;
  uint64_t h = fnv1a64(scene.dump());
  h = fnv1a64(render_settings_text(film), h);
  std::set<std::string> assets;
  collect_assets(doc, &assets);
  for (const std::string& a : assets) {
    std::error_code ec;
    const auto file = asset_root / a;
    if (std::filesystem::is_regular_file(file, ec)) h = fnv1a_file(fnv1a64(a, h), file);
  }
  return h;
}

}  // namespace tessera::cli
