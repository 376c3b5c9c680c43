// The fingerprint of a partial film (.tfilm, partial_film.h): what its pixels depend on, so that `tessera merge`
// refuses parts of different jobs or settings.
#pragma once

#include <cstdint>
#include <filesystem>

#include <nlohmann/json.hpp>

#include "renderer/render_settings.h"

namespace tessera::cli {

// FNV-1a of the job document without its "render", "outputs" and "priority", of the settings the film's sums depend
// on (through their JSON mapping, render_settings.h: size, seed, sampler, integrator, estimator, maximum depth; not
// the sample budget, which a part's sample range sets, the stopping rules, the display or the output formats), and of
// the bytes of the asset files the document names that exist under `asset_root`.
uint64_t film_fingerprint(const nlohmann::json& doc, const RenderSettings& settings,
                          const std::filesystem::path& asset_root);

}  // namespace tessera::cli
