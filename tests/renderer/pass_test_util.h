// Shared helpers for the render-pass tests (aov_test.cpp, cryptomatte_test.cpp): the Cornell box's scene and the
// settings of a small render with passes.
#pragma once

#include <fstream>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "renderer/render_settings.h"

namespace tessera::test {

// The scene of proto/examples/cornell.json (the tests run from the repository root).
inline nlohmann::json cornell_scene() {
  std::ifstream in("proto/examples/cornell.json");
  if (!in) throw std::runtime_error("run the tests from the repository root (proto/examples/cornell.json)");
  return nlohmann::json::parse(in)["scene"];
}

// w x h at spp samples a pixel by `integrator`, with the passes `aovs`; seed 7, tiles of 16.
inline RenderSettings settings(int w, int h, uint32_t spp, const std::string& integrator,
                               std::vector<std::string> aovs) {
  RenderSettings s;
  s.width = w;
  s.height = h;
  s.spp = spp;
  s.seed = 7;
  s.integrator.name = integrator;
  s.tile_size = 16;
  s.aovs = std::move(aovs);
  return s;
}

}  // namespace tessera::test
