// A resolved image of named layers, what the output pipeline (output.h) encodes, and the post stages that change it
// between resolve and encode (a denoiser, denoise.h): apart from the pipeline, so that a stage needs nothing of it.
#pragma once

#include <string>
#include <utility>
#include <vector>

namespace tessera {

// One layer of a resolved image: its channels interleaved per pixel, row-major.
struct ImageLayer {
  std::string name;                   // empty for the beauty, whose channels are stored as R, G, B
  std::vector<std::string> channels;  // "R", "G", "B"; a layer "albedo" is stored as albedo.R, albedo.G, ...
  std::vector<float> pixels;          // width * height * channels.size()
  bool always_float = false;          // stored as 32-bit float whatever the EXR precision (ids, depth, positions)
  bool named_in_full = false;         // `channels` are the stored names themselves (Cryptomatte's CryptoObject00.R)
};

struct Image {
  int width = 0;
  int height = 0;
  std::vector<ImageLayer> layers;  // the beauty first
  // String attributes of the EXR header (Cryptomatte's manifests), in order.
  std::vector<std::pair<std::string, std::string>> metadata;
  const ImageLayer& beauty() const { return layers.front(); }
};

// A stage between resolve and encode, applied to the linear image in place; deterministic (the same image gives
// the same bits on any machine and thread count).
class PostStage {
 public:
  virtual ~PostStage() = default;
  virtual const char* name() const = 0;
  virtual void apply(Image& image) const = 0;
};

}  // namespace tessera
