#include "renderer/film.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <stdexcept>

namespace tessera {

Film::Film(int width, int height)
    : width_(width), height_(height), sum_lum2_(pixel_count(), 0.0f), pixel_samples_(pixel_count(), 0) {
  beauty_.name = kBeauty;
  beauty_.channels = 3;
  beauty_.kind = LayerKind::kRadiance;
  beauty_.sums.assign(3 * pixel_count(), 0);
}

void Film::set_samples(uint32_t n) {
  samples_ = n;
  std::fill(pixel_samples_.begin(), pixel_samples_.end(), n);
}

void Film::set_samples(uint32_t n, int x, int y, int w, int h) {
  samples_ = n;
  for (int py = 0; py < height_; ++py)
    for (int px = 0; px < width_; ++px)
      pixel_samples_[index(px, py)] = px >= x && px < x + w && py >= y && py < y + h ? n : 0;
}

void Film::advance_samples(uint32_t n, const std::vector<uint8_t>& active) {
  if (active.size() != pixel_samples_.size()) throw std::invalid_argument("a pixel mask of another size");
  samples_ += n;
  for (size_t i = 0; i < pixel_samples_.size(); ++i)
    if (active[i]) pixel_samples_[i] += n;
}

int Film::add_layer(std::string name, int channels, LayerKind kind) {
  if (name.empty() || name.size() > kMaxNameLength)
    throw std::invalid_argument("a film layer's name has 1 to " + std::to_string(kMaxNameLength) + " characters");
  for (char c : name)
    if (c <= ' ' || c > '~') throw std::invalid_argument("a film layer's name is printable ASCII without spaces");
  if (layer(name) >= 0) throw std::invalid_argument("the film already has a layer " + name);
  if (channels < 1 || channels > kMaxChannels || (kind == LayerKind::kDistance && channels != 1) ||
      (kind == LayerKind::kIds && channels % 2 != 0))
    throw std::invalid_argument("film layer " + name + ": bad channel count");
  if (kind != LayerKind::kRadiance && kind != LayerKind::kSigned && kind != LayerKind::kDistance &&
      kind != LayerKind::kIds)
    throw std::invalid_argument("film layer " + name + ": unknown kind");
  if (layer_count() >= kMaxLayers) throw std::invalid_argument("a film holds at most 64 layers");
  FilmLayer l;
  l.name = std::move(name);
  l.channels = channels;
  l.kind = kind;
  if (kind == LayerKind::kIds)
    l.ids.resize(pixel_count());
  else
    l.sums.assign(static_cast<size_t>(channels) * pixel_count(), 0);
  if (kind == LayerKind::kDistance) l.hits.assign(pixel_count(), 0);
  extra_.push_back(std::move(l));
  return layer_count() - 1;
}

int Film::layer(std::string_view name) const {
  for (int i = 0; i < layer_count(); ++i)
    if (layer_at(i).name == name) return i;
  return -1;
}

bool Film::same_layout(const Film& other) const {
  if (other.width_ != width_ || other.height_ != height_ || other.layer_count() != layer_count()) return false;
  for (int i = 0; i < layer_count(); ++i) {
    const FilmLayer &a = layer_at(i), &b = other.layer_at(i);
    if (a.name != b.name || a.channels != b.channels || a.kind != b.kind) return false;
  }
  return true;
}

void Film::add_layer_sample(int layer, int x, int y, const float* values) {
  if (layer == 0) return add_sample(x, y, Rgb(values[0], values[1], values[2]));
  FilmLayer& l = layer_at(layer);
  const size_t i = index(x, y), c = static_cast<size_t>(l.channels);
  switch (l.kind) {
    case LayerKind::kRadiance:
      for (size_t k = 0; k < c; ++k) l.sums[c * i + k] += to_fixed(values[k]);
      break;
    case LayerKind::kSigned:
      for (size_t k = 0; k < c; ++k) l.sums[c * i + k] += to_fixed_signed(values[k]);
      break;
    case LayerKind::kDistance:
      if (std::isfinite(values[0]) && values[0] >= 0) {
        l.sums[i] += to_fixed(values[0]);
        l.hits[i] += 1;
      }
      break;
    case LayerKind::kIds:
      throw std::invalid_argument("film layer " + l.name + " counts ids: add_id_sample");
  }
}

void Film::add_id_sample(int layer, int x, int y, uint32_t id) {
  std::vector<IdCount>& ids = layer_at(layer).ids[index(x, y)];
  auto it = std::lower_bound(ids.begin(), ids.end(), id, [](const IdCount& e, uint32_t v) { return e.id < v; });
  if (it != ids.end() && it->id == id)
    ++it->count;
  else if (ids.size() < kMaxIdsPerPixel)
    ids.insert(it, IdCount{id, 1});
}

void Film::add_layer_sample_shared(int layer, int x, int y, const float* values) {
  if (layer == 0) return splat(x, y, Rgb(values[0], values[1], values[2]));
  FilmLayer& l = layer_at(layer);
  const size_t i = index(x, y), c = static_cast<size_t>(l.channels);
  switch (l.kind) {
    case LayerKind::kRadiance:
      for (size_t k = 0; k < c; ++k) atomic_add(l.sums[c * i + k], to_fixed(values[k]));
      break;
    case LayerKind::kSigned:
      for (size_t k = 0; k < c; ++k) atomic_add(l.sums[c * i + k], to_fixed_signed(values[k]));
      break;
    case LayerKind::kDistance:
      if (std::isfinite(values[0]) && values[0] >= 0) {
        atomic_add(l.sums[i], to_fixed(values[0]));
        __atomic_fetch_add(&l.hits[i], 1u, __ATOMIC_RELAXED);
      }
      break;
    case LayerKind::kIds:
      throw std::invalid_argument("film layer " + l.name + " counts ids: add_id_sample");
  }
}

std::vector<float> Film::resolve() const {
  std::vector<float> out(beauty_.sums.size());
  for (size_t i = 0; i < pixel_count(); ++i) {
    const uint32_t n = mean_divisor(i);
    const double inv = n > 0 ? 1.0 / (kFixedScale * n) : 0.0;
    for (size_t c = 0; c < 3; ++c)
      out[3 * i + c] = static_cast<float>(static_cast<double>(beauty_.sums[3 * i + c]) * inv);
  }
  return out;
}

namespace {

// The ranks of an id layer: per pixel, channels / 2 pairs (id, coverage).
std::vector<float> resolve_ids(const FilmLayer& l, const std::vector<uint32_t>& pixel_samples) {
  const size_t c = static_cast<size_t>(l.channels), ranks = c / 2;
  std::vector<float> out(c * l.ids.size(), 0.0f);
  std::vector<IdCount> ranked;
  for (size_t i = 0; i < l.ids.size(); ++i) {
    ranked = l.ids[i];
    std::sort(ranked.begin(), ranked.end(),
              [](const IdCount& a, const IdCount& b) { return a.count != b.count ? a.count > b.count : a.id < b.id; });
    const double n = pixel_samples[i];
    for (size_t r = 0; r < std::min(ranks, ranked.size()); ++r) {
      float id;
      static_assert(sizeof id == sizeof ranked[r].id);
      std::memcpy(&id, &ranked[r].id, sizeof id);
      out[c * i + 2 * r] = id;
      out[c * i + 2 * r + 1] = n > 0 ? static_cast<float>(ranked[r].count / n) : 0.0f;
    }
  }
  return out;
}

// The ids of `a` and `b` together, counts added; the kMaxIdsPerPixel of most samples (ties to the lower id) when
// there are more.
void merge_ids(std::vector<IdCount>& a, const std::vector<IdCount>& b, size_t max_ids) {
  if (b.empty()) return;
  std::vector<IdCount> joined;
  joined.reserve(a.size() + b.size());
  size_t i = 0, j = 0;
  while (i < a.size() || j < b.size()) {
    if (j == b.size() || (i < a.size() && a[i].id < b[j].id))
      joined.push_back(a[i++]);
    else if (i == a.size() || b[j].id < a[i].id)
      joined.push_back(b[j++]);
    else
      joined.push_back(IdCount{a[i].id, a[i++].count + b[j++].count});
  }
  if (joined.size() > max_ids) {
    std::sort(joined.begin(), joined.end(),
              [](const IdCount& x, const IdCount& y) { return x.count != y.count ? x.count > y.count : x.id < y.id; });
    joined.resize(max_ids);
    std::sort(joined.begin(), joined.end(), [](const IdCount& x, const IdCount& y) { return x.id < y.id; });
  }
  a = std::move(joined);
}

}  // namespace

std::vector<float> Film::resolve_layer(int layer) const {
  const FilmLayer& l = layer_at(layer);
  if (l.kind == LayerKind::kIds) return resolve_ids(l, pixel_samples_);
  const size_t c = static_cast<size_t>(l.channels);
  std::vector<float> out(l.sums.size());
  for (size_t i = 0; i < pixel_count(); ++i) {
    // The same arithmetic as resolve(): a film whose pixels all have samples() samples resolves to the same bits.
    const uint32_t n = l.kind == LayerKind::kDistance ? l.hits[i] : pixel_samples_[i];
    const double inv = n > 0 ? 1.0 / (kFixedScale * n) : 0.0;
    for (size_t k = 0; k < c; ++k)
      out[c * i + k] = l.kind == LayerKind::kDistance && n == 0
                           ? INFINITY
                           : static_cast<float>(static_cast<double>(l.sums[c * i + k]) * inv);
  }
  return out;
}

std::vector<float> Film::resolve_layer(std::string_view name) const {
  const int i = layer(name);
  if (i < 0) throw std::invalid_argument("the film has no layer " + std::string(name));
  return resolve_layer(i);
}

void Film::merge(const Film& other) {
  if (!same_layout(other)) throw std::invalid_argument("films of different sizes or layers");
  for (int k = 0; k < layer_count(); ++k) {
    FilmLayer& a = layer_at(k);
    const FilmLayer& b = other.layer_at(k);
    for (size_t i = 0; i < a.sums.size(); ++i) a.sums[i] += b.sums[i];
    for (size_t i = 0; i < a.hits.size(); ++i) a.hits[i] += b.hits[i];
    for (size_t i = 0; i < a.ids.size(); ++i) merge_ids(a.ids[i], b.ids[i], kMaxIdsPerPixel);
    a.manifest.insert(b.manifest.begin(), b.manifest.end());
  }
  for (size_t i = 0; i < sum_lum2_.size(); ++i) sum_lum2_[i] += other.sum_lum2_[i];
  for (size_t i = 0; i < pixel_samples_.size(); ++i) pixel_samples_[i] += other.pixel_samples_[i];
  samples_ += other.samples_;
}

double Film::relative_error() const {
  if (samples_ < 2) return INFINITY;
  double var_sum = 0, lum_sum = 0;
  size_t count = 0;
  const FixedSums& sum = beauty_.sums;
  for (size_t i = 0; i < pixel_count(); ++i) {
    const double n = mean_divisor(i);
    double mean = (0.2126 * static_cast<double>(sum[3 * i]) + 0.7152 * static_cast<double>(sum[3 * i + 1]) +
                   0.0722 * static_cast<double>(sum[3 * i + 2])) /
                  (kFixedScale * n);
    double var = (sum_lum2_[i] / n - mean * mean) * n / (n - 1);  // unbiased sample variance
    if (n < 2 || var < 0) var = 0;                                // a pixel of one sample has no variance to measure
    var_sum += var / n;                                           // variance of the pixel mean
    lum_sum += mean;
    ++count;
  }
  if (count == 0 || lum_sum <= 0) return INFINITY;
  double mean_lum = lum_sum / count;
  double rms_error = std::sqrt(var_sum / count);
  return rms_error / mean_lum;
}

}  // namespace tessera
