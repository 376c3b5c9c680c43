// Fuzz target: a glTF asset, binary (.glb) or JSON (.gltf), through tessera::import_gltf as a job's scene imports it:
// the container, tinygltf's parser, accessors, Draco and meshopt streams, KTX2 detection and the image decoders
// (PNG, JPEG, ... through OpenImageIO), materials, nodes and lights. The limits are small so an input runs in
// milliseconds. The loader's contract: an asset it cannot import is a SceneError (LoadStopped is for a stop token,
// never asked here); any other exception, a crash or a sanitizer report is a finding.
#include <cstddef>
#include <cstdint>

#include "renderer/gltf/container.h"
#include "renderer/gltf/loader.h"
#include "renderer/scene_error.h"
#include "renderer/thread_pool.h"
#include "tests/fuzz/fuzz_files.h"

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  // Images are decoded on the fuzzing thread: the same input covers the same code every run.
  tessera::limit_parallel_helpers(0);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  tessera::GltfImportOptions options;
  options.max_triangles = 20'000;
  options.max_vertices = 20'000;
  options.max_decoded_bytes = size_t{4} << 20;
  options.max_texture_pixels = 64 * 64;
  options.max_instances = 1'000;
  // The file's extension tells the loader how to read it; the bytes tell which this input is, as a .glb's magic
  // does (the same test is_glb makes).
  const bool binary = tessera::is_glb({reinterpret_cast<const char*>(data), size});
  const auto path = tessera::fuzz::write_input(binary ? "asset.glb" : "asset.gltf", data, size);
  tessera::Scene scene;
  try {
    tessera::import_gltf(path, "/scene/gltf", scene, options);
  } catch (const tessera::SceneError&) {
  } catch (const tessera::LoadStopped&) {
  }
  return 0;
}
