// Small vector algebra for the renderer: 3-vectors of float, used for points, directions and RGB radiance.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace tessera {

inline constexpr float kPi = 3.14159265358979323846f;
inline constexpr float kInvPi = 0.31830988618379067154f;
inline constexpr float kInv2Pi = 0.15915494309189533577f;
inline constexpr float kInv4Pi = 0.07957747154594766788f;
inline constexpr float kInfinity = std::numeric_limits<float>::infinity();

// atan2(y, x) in [-pi, pi]: the angle folded into [0, pi/4] (t = min/max of |x|, |y|), there the odd polynomial of
// Abramowitz and Stegun 4.4.49 (|error| <= 2e-8), then unfolded. Several times faster than the library call, which
// ran twice for every environment lookup. atan2(0, 0) is 0 (or pi from -0 or negative x, as the library's).
inline float fast_atan2(float y, float x) {
  const float ax = std::abs(x), ay = std::abs(y);
  const float hi = std::max(ax, ay), lo = std::min(ax, ay);
  const float t = hi > 0 ? lo / hi : 0.0f;
  const float t2 = t * t;
  float r =
      t * (1.0f + t2 * (-0.3333314528f +
                        t2 * (0.1999355085f +
                              t2 * (-0.1420889944f +
                                    t2 * (0.1065626393f +
                                          t2 * (-0.0752896400f +
                                                t2 * (0.0429096138f + t2 * (-0.0161657367f + t2 * 0.0028662257f))))))));
  if (ay > ax) r = 1.57079632679489661923f - r;
  if (std::signbit(x)) r = kPi - r;
  return std::copysign(r, y);
}

struct Vec2 {
  float x = 0, y = 0;
  constexpr Vec2() = default;
  constexpr Vec2(float x_, float y_) : x(x_), y(y_) {}
  constexpr Vec2 operator+(Vec2 b) const { return {x + b.x, y + b.y}; }
  constexpr Vec2 operator-(Vec2 b) const { return {x - b.x, y - b.y}; }
  constexpr Vec2 operator*(float s) const { return {x * s, y * s}; }
  constexpr bool operator==(const Vec2&) const = default;
};

struct Vec3 {
  float x = 0, y = 0, z = 0;
  constexpr Vec3() = default;
  constexpr explicit Vec3(float s) : x(s), y(s), z(s) {}
  constexpr Vec3(float x_, float y_, float z_) : x(x_), y(y_), z(z_) {}
  constexpr float operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }
  constexpr float& operator[](int i) { return i == 0 ? x : (i == 1 ? y : z); }
  constexpr Vec3 operator-() const { return {-x, -y, -z}; }
  constexpr Vec3 operator+(const Vec3& b) const { return {x + b.x, y + b.y, z + b.z}; }
  constexpr Vec3 operator-(const Vec3& b) const { return {x - b.x, y - b.y, z - b.z}; }
  constexpr Vec3 operator*(const Vec3& b) const { return {x * b.x, y * b.y, z * b.z}; }
  constexpr Vec3 operator/(const Vec3& b) const { return {x / b.x, y / b.y, z / b.z}; }
  constexpr Vec3 operator*(float s) const { return {x * s, y * s, z * s}; }
  constexpr Vec3 operator/(float s) const { return {x / s, y / s, z / s}; }
  constexpr Vec3& operator+=(const Vec3& b) {
    x += b.x;
    y += b.y;
    z += b.z;
    return *this;
  }
  constexpr Vec3& operator-=(const Vec3& b) {
    x -= b.x;
    y -= b.y;
    z -= b.z;
    return *this;
  }
  constexpr Vec3& operator*=(const Vec3& b) {
    x *= b.x;
    y *= b.y;
    z *= b.z;
    return *this;
  }
  constexpr Vec3& operator*=(float s) {
    x *= s;
    y *= s;
    z *= s;
    return *this;
  }
  constexpr Vec3& operator/=(float s) {
    x /= s;
    y /= s;
    z /= s;
    return *this;
  }
  constexpr bool operator==(const Vec3&) const = default;
};
constexpr Vec3 operator*(float s, const Vec3& v) {
  return v * s;
}

// Linear RGB radiance, reflectance or throughput.
using Rgb = Vec3;

constexpr float dot(const Vec3& a, const Vec3& b) {
  return a.x * b.x + a.y * b.y + a.z * b.z;
}
constexpr Vec3 cross(const Vec3& a, const Vec3& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline float length(const Vec3& v) {
  return std::sqrt(dot(v, v));
}
constexpr float length_squared(const Vec3& v) {
  return dot(v, v);
}
inline Vec3 normalize(const Vec3& v) {
  return v / length(v);
}
inline Vec3 vabs(const Vec3& v) {
  return {std::abs(v.x), std::abs(v.y), std::abs(v.z)};
}
inline Vec3 vmin(const Vec3& a, const Vec3& b) {
  return {std::min(a.x, b.x), std::min(a.y, b.y), std::min(a.z, b.z)};
}
inline Vec3 vmax(const Vec3& a, const Vec3& b) {
  return {std::max(a.x, b.x), std::max(a.y, b.y), std::max(a.z, b.z)};
}
constexpr float max_component(const Vec3& v) {
  return std::max(v.x, std::max(v.y, v.z));
}
constexpr bool is_black(const Vec3& v) {
  return v.x == 0 && v.y == 0 && v.z == 0;
}
inline bool is_finite(const Vec3& v) {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}
// Rec. 709 / sRGB luminance of linear RGB.
constexpr float luminance(const Rgb& c) {
  return 0.2126f * c.x + 0.7152f * c.y + 0.0722f * c.z;
}
constexpr float average(const Rgb& c) {
  return (c.x + c.y + c.z) * (1.0f / 3.0f);
}

inline Vec3 reflect(const Vec3& wo, const Vec3& n) {
  return -wo + n * (2 * dot(wo, n));
}

// Orthonormal basis with `n` as its z axis (Duff et al., "Building an Orthonormal Basis, Revisited", JCGT 2017).
struct Frame {
  Vec3 s, t, n;
  Frame() : s(1, 0, 0), t(0, 1, 0), n(0, 0, 1) {}
  Frame(const Vec3& s_, const Vec3& t_, const Vec3& n_) : s(s_), t(t_), n(n_) {}
  static Frame from_normal(const Vec3& n) {
    float sign = std::copysign(1.0f, n.z);
    float a = -1.0f / (sign + n.z);
    float b = n.x * n.y * a;
    return Frame(Vec3(1 + sign * n.x * n.x * a, sign * b, -sign * n.x), Vec3(b, sign + n.y * n.y * a, -n.y), n);
  }
  // Frame with normal n whose s axis follows the tangent direction `tangent` projected into the plane.
  static Frame from_normal_tangent(const Vec3& n, const Vec3& tangent) {
    Vec3 s = tangent - n * dot(n, tangent);
    float len2 = length_squared(s);
    if (!(len2 > 1e-12f)) return from_normal(n);
    s = s / std::sqrt(len2);
    return Frame(s, cross(n, s), n);
  }
  Vec3 to_local(const Vec3& v) const { return {dot(v, s), dot(v, t), dot(v, n)}; }
  Vec3 to_world(const Vec3& v) const { return s * v.x + t * v.y + n * v.z; }
};

struct Ray {
  Vec3 origin;
  Vec3 dir;
  float tmin = 0;
  float tmax = kInfinity;
  // When within the shutter the ray is traced, in [0, 1] from its opening to its closing (Embree's RTCRay::time):
  // moving geometry is hit where it is at that time. Every ray of a path carries the camera sample's time.
  float time = 0;
};

// A ray's cone (Akenine-Möller et al., "Texture Level of Detail Strategies for Real-Time Ray Tracing", 2019): the
// width of the beam of rays it stands for at its origin, and how fast that width grows per unit of distance. Its
// width where it hits, over the surface's texture stretch, picks the mip level textures are read at.
struct RayCone {
  float width = 0;
  float spread = 0;
  // The width at a distance along the ray (in units of length, not of t over an unnormalised direction).
  float width_at(float distance) const { return width + spread * distance; }
};

// Affine transform: a 3x4 row-major matrix, the last row implied 0 0 0 1. Float for rendering (Transform); double
// where transforms are composed before rendering (TransformD: a glTF node chain, a skin's joints), cast at the end.
template <typename T>
struct BasicTransform {
  T m[3][4] = {{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}};
  Vec3 point(const Vec3& p) const {
    return {static_cast<float>(m[0][0] * p.x + m[0][1] * p.y + m[0][2] * p.z + m[0][3]),
            static_cast<float>(m[1][0] * p.x + m[1][1] * p.y + m[1][2] * p.z + m[1][3]),
            static_cast<float>(m[2][0] * p.x + m[2][1] * p.y + m[2][2] * p.z + m[2][3])};
  }
  Vec3 vector(const Vec3& v) const {
    return {static_cast<float>(m[0][0] * v.x + m[0][1] * v.y + m[0][2] * v.z),
            static_cast<float>(m[1][0] * v.x + m[1][1] * v.y + m[1][2] * v.z),
            static_cast<float>(m[2][0] * v.x + m[2][1] * v.y + m[2][2] * v.z)};
  }
  // This transform after `b` (this * b).
  BasicTransform operator*(const BasicTransform& b) const {
    BasicTransform r;
    for (int row = 0; row < 3; ++row)
      for (int col = 0; col < 4; ++col) {
        T s = 0;
        for (int k = 0; k < 3; ++k) s += m[row][k] * b.m[k][col];
        if (col == 3) s += m[row][3];
        r.m[row][col] = s;
      }
    return r;
  }
  // The determinant of the linear part: negative for a mirroring transform.
  T determinant() const {
    return m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
           m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
  }
  // The inverse transpose of the linear part, without translation: what normals are transformed by (cofactors over
  // the determinant); the identity for a singular transform.
  BasicTransform normal_transform() const {
    const T d = determinant();
    BasicTransform n;
    if (d == 0) return n;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) {
        const int r1 = (r + 1) % 3, r2 = (r + 2) % 3, c1 = (c + 1) % 3, c2 = (c + 2) % 3;
        n.m[r][c] = (m[r1][c1] * m[r2][c2] - m[r1][c2] * m[r2][c1]) / d;
      }
    for (int r = 0; r < 3; ++r) n.m[r][3] = 0;
    return n;
  }
  // From a column-major 4x4 matrix (glTF's and OpenGL's layout), whose last row is dropped.
  static BasicTransform from_column_major(const T* c) {
    BasicTransform t;
    for (int row = 0; row < 3; ++row)
      for (int col = 0; col < 4; ++col) t.m[row][col] = c[col * 4 + row];
    return t;
  }
  // Translation * rotation * scale, the rotation a unit quaternion (x, y, z, w) (glTF 2.0, 5.25 node.rotation).
  static BasicTransform from_trs(const T translation[3], const T quaternion[4], const T scale[3]) {
    const T x = quaternion[0], y = quaternion[1], z = quaternion[2], w = quaternion[3];
    const T r[3][3] = {{1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)},
                       {2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)},
                       {2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)}};
    BasicTransform t;
    for (int row = 0; row < 3; ++row) {
      for (int col = 0; col < 3; ++col) t.m[row][col] = r[row][col] * scale[col];
      t.m[row][3] = translation[row];
    }
    return t;
  }
  template <typename U>
  BasicTransform<U> cast() const {
    BasicTransform<U> t;
    for (int row = 0; row < 3; ++row)
      for (int col = 0; col < 4; ++col) t.m[row][col] = static_cast<U>(m[row][col]);
    return t;
  }
};
using Transform = BasicTransform<float>;
using TransformD = BasicTransform<double>;

template <typename T>
constexpr T clamp(T v, T lo, T hi) {
  return v < lo ? lo : (v > hi ? hi : v);
}
constexpr float sqr(float x) {
  return x * x;
}
// a if `mask` else b, without a branch: for conditions that are a coin toss per sample, where a mispredicted branch
// costs more than computing both sides (compilers turn a plain ?: on floats back into a branch). `mask` comes from
// greater_mask.
#if defined(__SSE2__)
using FloatMask = __m128;
inline FloatMask greater_mask(float a, float b) {
  return _mm_cmpgt_ss(_mm_set_ss(a), _mm_set_ss(b));
}
inline float select(FloatMask mask, float a, float b) {
  return _mm_cvtss_f32(_mm_or_ps(_mm_and_ps(mask, _mm_set_ss(a)), _mm_andnot_ps(mask, _mm_set_ss(b))));
}
#else
using FloatMask = bool;
inline FloatMask greater_mask(float a, float b) {
  return a > b;
}
inline float select(FloatMask mask, float a, float b) {
  return mask ? a : b;
}
#endif

inline float safe_sqrt(float x) {
  return std::sqrt(std::max(0.0f, x));
}

}  // namespace tessera
