// Deterministic random numbers: every value depends only on (seed, pixel, sample index, dimension), so an image is
// the same whatever the thread count, tile order or pass boundaries, and a render resumed at sample N continues
// exactly where an uninterrupted one would.
#pragma once

#include <cstdint>

#include "renderer/math.h"

namespace tessera {

// 64-bit finaliser of SplitMix64 / MurmurHash3: a bijective mix with full avalanche.
constexpr uint64_t mix64(uint64_t x) {
  x ^= x >> 30;
  x *= 0xbf58476d1ce4e5b9ULL;
  x ^= x >> 27;
  x *= 0x94d049bb133111ebULL;
  x ^= x >> 31;
  return x;
}

// Which sequence a PixelSampler draws from.
enum class SamplerKind {
  kIndependent,  // hashed uniform numbers: every dimension independent
  kSobol,        // Owen-scrambled, index-shuffled 2D Sobol per dimension pair (Burley 2020)
};

namespace sobol_detail {

inline uint32_t reverse_bits(uint32_t x) {
  x = __builtin_bswap32(x);  // bytes in one instruction, then the bits within each byte
  x = ((x >> 4) & 0x0f0f0f0fu) | ((x & 0x0f0f0f0fu) << 4);
  x = ((x >> 2) & 0x33333333u) | ((x & 0x33333333u) << 2);
  return ((x >> 1) & 0x55555555u) | ((x & 0x55555555u) << 1);
}

// Laine-Karras style hash in which each bit depends only on the bits below it: applied to bit-reversed values it
// is a nested uniform (Owen) scramble (Burley, "Practical Hash-based Owen Scrambling", JCGT 2020, listing 1,
// with the improved constants of its later revision).
inline uint32_t laine_karras_permutation(uint32_t x, uint32_t seed) {
  x ^= x * 0x3d20adeau;
  x += seed;
  x *= (seed >> 16) | 1u;
  x ^= x * 0x05526c56u;
  x ^= x * 0x53a22864u;
  return x;
}

// Dimension 1 of the Sobol sequence (primitive polynomial x + 1) is a linear map over GF(2) of the index bits:
// XOR the direction numbers of its set bits. Tabulated per byte, that is four lookups. Bit reversal is linear over
// GF(2) too, so the tables are indexed by the bytes of the reversed index (which the shuffle makes) and hold the
// reversed direction numbers (which the Owen scramble, starting by reversing the value, reads): no reversal on
// either side.
constexpr uint32_t reverse_bits_constexpr(uint32_t x) {
  uint32_t r = 0;
  for (int i = 0; i < 32; ++i) r |= ((x >> i) & 1u) << (31 - i);
  return r;
}

struct SobolDim1ReversedTables {
  uint32_t t[4][256] = {};
  constexpr SobolDim1ReversedTables() {
    uint32_t v[32] = {};
    v[0] = 1u << 31;
    for (int k = 1; k < 32; ++k) v[k] = v[k - 1] ^ (v[k - 1] >> 1);
    for (int b = 0; b < 4; ++b)
      for (int x = 0; x < 256; ++x) {
        uint32_t r = 0;
        // Byte b of the reversed index holds index bits 31 - 8b - k for its bits k.
        for (int k = 0; k < 8; ++k)
          if (x & (1 << k)) r ^= v[31 - (8 * b + k)];
        t[b][x] = reverse_bits_constexpr(r);
      }
  }
};

// Built by the compiler: no guard on every lookup.
inline constexpr SobolDim1ReversedTables kSobolDim1ReversedTables{};

// reverse_bits(Sobol dimension 1 of index), from reverse_bits(index).
inline uint32_t sobol_dim1_reversed(uint32_t reversed_index) {
  const auto& t = kSobolDim1ReversedTables.t;
  return t[0][reversed_index & 0xff] ^ t[1][(reversed_index >> 8) & 0xff] ^ t[2][(reversed_index >> 16) & 0xff] ^
         t[3][reversed_index >> 24];
}

}  // namespace sobol_detail

class PixelSampler {
 public:
  // What a render's seed contributes to every pixel's numbers: computed once per render rather than per sample.
  struct SeedKeys {
    explicit SeedKeys(uint64_t seed)
        : independent(mix64(seed ^ 0x9e3779b97f4a7c15ULL)), pixel(mix64(seed ^ 0x5851f42d4c957f2dULL)) {}
    uint64_t independent, pixel;
  };

  PixelSampler() = default;  // a placeholder, to be assigned before use
  PixelSampler(uint64_t seed, uint32_t pixel_index, uint64_t sample_index, SamplerKind kind = SamplerKind::kIndependent)
      : PixelSampler(SeedKeys(seed), pixel_index, sample_index, kind) {}
  PixelSampler(const SeedKeys& keys, uint32_t pixel_index, uint64_t sample_index,
               SamplerKind kind = SamplerKind::kIndependent)
      // The independent sampler's key (the Sobol sampler does not read it).
      : key_(kind == SamplerKind::kIndependent
                 ? mix64(keys.independent + pixel_index) ^ mix64(sample_index + 0x632be59bd9b4e019ULL)
                 : 0),
        pixel_key_(mix64(keys.pixel + pixel_index)),
        reversed_index_(sobol_detail::reverse_bits(static_cast<uint32_t>(sample_index))),
        kind_(kind) {}

  // Next uniform number in [0, 1).
  float get1d() { return get1d_at(++dimension_); }
  // Next pair of uniform numbers in [0, 1)^2, stratified jointly with the Sobol sampler.
  Vec2 get2d() {
    if (kind_ == SamplerKind::kSobol) {
      // Each dimension pair of each pixel gets its own shuffle of the sample order and its own scramble, so pairs
      // are decorrelated from each other and pixels from their neighbours.
      const uint64_t h = mix64(pixel_key_ + 0x9e3779b97f4a7c15ULL * ++dimension_);
      const uint32_t reversed = shuffled_reversed_index(h);
      const uint32_t x = sobol_dim0(sobol_detail::reverse_bits(reversed), h);
      // Owen-scrambled Sobol dimension 1: reverse(LK(reverse(dim1(index)))), the inner reversal from the tables,
      // which read the reversed index (one reversal fewer on the way to y).
      const uint32_t y = sobol_detail::reverse_bits(sobol_detail::laine_karras_permutation(
          sobol_detail::sobol_dim1_reversed(reversed), static_cast<uint32_t>(mix64(h) >> 32)));
      return {static_cast<float>(x >> 8) * 0x1p-24f, static_cast<float>(y >> 8) * 0x1p-24f};
    }
    float a = get1d();
    return {a, get1d()};
  }
  // The number of dimension 0, which get1d() and get2d() never reach (they start at 1): for a choice the whole sample
  // makes once, where only some samples make it (the wavelength of a path through a dispersive material), drawn
  // without moving any other number. Stratified over the pixel's samples as dimension 1 is.
  float get1d_dimension0() const { return get1d_at(0); }
  // The number of the dimension reserved for a camera sample's time within the shutter (motion blur), which get1d()
  // and get2d() never reach either: drawn only where something moves, so that no other number moves with it and a
  // still scene keeps its bits. Stratified over the pixel's samples as dimension 0 is.
  static constexpr uint32_t kTimeDimension = 0xffffffffu;
  float get1d_time() const { return get1d_at(kTimeDimension); }
  // Steps over the dimensions a get1d() or get2d() would use, without computing them: for numbers a caller draws
  // only to keep the dimension layout fixed and would not use. Every later number is the same as after the call.
  void skip1d() { ++dimension_; }
  void skip2d() { dimension_ += kind_ == SamplerKind::kSobol ? 1 : 2; }
  uint32_t dimension() const { return dimension_; }

 private:
  // The number of dimension `dimension`.
  float get1d_at(uint32_t dimension) const {
    if (kind_ == SamplerKind::kSobol) {
      // One dimension: the shuffled, scrambled van der Corput sequence (Sobol's dimension 0).
      const uint64_t h = mix64(pixel_key_ + 0x9e3779b97f4a7c15ULL * dimension);
      return static_cast<float>(sobol_dim0(shuffled_index(h), h) >> 8) * 0x1p-24f;
    }
    return to_unit(mix64(key_ + 0x9e3779b97f4a7c15ULL * dimension));
  }
  // The sample index shuffled by the dimension pair's hash h, by the Owen scramble reverse(LK(reverse(i))), with
  // reverse(i) computed once per sample.
  uint32_t shuffled_index(uint64_t h) const { return sobol_detail::reverse_bits(shuffled_reversed_index(h)); }
  // The same, bit-reversed: LK(reverse(i)).
  uint32_t shuffled_reversed_index(uint64_t h) const {
    return sobol_detail::laine_karras_permutation(reversed_index_, static_cast<uint32_t>(h));
  }
  // Dimension 0 (van der Corput, reverse(index)) scrambled: reverse(LK(reverse(reverse(index)))), the inner
  // reversals cancelling.
  static uint32_t sobol_dim0(uint32_t index, uint64_t h) {
    return sobol_detail::reverse_bits(sobol_detail::laine_karras_permutation(index, static_cast<uint32_t>(h >> 32)));
  }
  static float to_unit(uint64_t bits) {
    // 24 high bits give every float in [0, 1) on a 2^-24 grid; never returns 1.
    return static_cast<float>(bits >> 40) * 0x1p-24f;
  }
  uint64_t key_ = 0;
  uint64_t pixel_key_ = 0;
  uint32_t reversed_index_ = 0;  // the sample index, bit-reversed (Sobol indices are 32-bit)
  SamplerKind kind_ = SamplerKind::kIndependent;
  uint32_t dimension_ = 0;
};

}  // namespace tessera
