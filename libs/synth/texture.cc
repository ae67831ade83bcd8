#include "synth/texture.h"

#include <algorithm>
#include <array>
#include <cmath>

namespace lfrecon::synth {
namespace {

std::uint64_t SplitMix64(std::uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

// Permutation table built once with our own Fisher-Yates (std::shuffle is not
// specified exactly, and the textures must be the same everywhere).
struct PermutationTable {
  std::array<int, 512> p{};
  PermutationTable() {
    std::array<int, 256> perm{};
    for (int i = 0; i < 256; ++i) perm[i] = i;
    std::uint64_t state = 0x5EEDF00Dull;
    for (int i = 255; i > 0; --i) {
      state = SplitMix64(state);
      const int j = static_cast<int>(state % static_cast<std::uint64_t>(i + 1));
      std::swap(perm[i], perm[j]);
    }
    for (int i = 0; i < 512; ++i) p[i] = perm[i & 255];
  }
};

const PermutationTable& Perm() {
  static const PermutationTable table;
  return table;
}

inline double Fade(double t) { return t * t * t * (t * (t * 6 - 15) + 10); }
inline double Lerp(double t, double a, double b) { return a + t * (b - a); }

// Perlin's 12 edge gradients padded to 16 (as his `grad` switch does), as a
// table: a branch per corner on a random hash mispredicts about half the time
// and dominated the render time.
struct Gradient {
  double x, y, z;
};
constexpr Gradient kGradients[16] = {
    {1, 1, 0}, {-1, 1, 0}, {1, -1, 0}, {-1, -1, 0}, {1, 0, 1}, {-1, 0, 1}, {1, 0, -1}, {-1, 0, -1},
    {0, 1, 1}, {0, -1, 1}, {0, 1, -1}, {0, -1, -1}, {1, 1, 0}, {0, -1, 1}, {-1, 1, 0}, {0, -1, -1}};
inline double Grad(int hash, double x, double y, double z) {
  const Gradient& g = kGradients[hash & 15];
  return g.x * x + g.y * y + g.z * z;
}

// sin(x) / x on [0, pi] (0 beyond) from Bhaskara's rational approximation of
// sin, scaled to 1 at 0 (error < 0.02: plenty for a filter weight); libm's sin
// per octave was a tenth of the render time.
inline double Sinc(double x) {
  if (x >= M_PI) return 0.0;
  if (x <= 0) return 1.0;
  return 5.0 * M_PI * (M_PI - x) / (5.0 * M_PI * M_PI - 4.0 * x * (M_PI - x));
}

inline float Clamp01(double v) { return static_cast<float>(std::clamp(v, 0.0, 1.0)); }

Eigen::Vector3f Mix(const Material& m, double t) {
  const float f = Clamp01(t);
  return m.color_a + f * (m.color_b - m.color_a);
}

}  // namespace

std::string TextureTypeName(TextureType type) {
  switch (type) {
    case TextureType::kFlat:
      return "flat";
    case TextureType::kNoise:
      return "noise";
    case TextureType::kChecker:
      return "checker";
    case TextureType::kStripes:
      return "stripes";
  }
  return "unknown";
}

std::uint64_t HashCombine(std::uint64_t a, std::uint64_t b) { return SplitMix64(a ^ SplitMix64(b)); }

double PerlinNoise(double x, double y, double z) {
  const auto& p = Perm().p;
  // Integer floor without a libm call (baseline x86-64 has no inline floor);
  // inputs are far below 2^62 in magnitude.
  auto ifloor = [](double v) {
    const long long i = static_cast<long long>(v);
    return i - (v < static_cast<double>(i));
  };
  const long long ix = ifloor(x), iy = ifloor(y), iz = ifloor(z);
  const double fx = static_cast<double>(ix), fy = static_cast<double>(iy), fz = static_cast<double>(iz);
  // The table is 512 long, so X + 1 etc. never need wrapping.
  const int X = static_cast<int>(ix & 255), Y = static_cast<int>(iy & 255), Z = static_cast<int>(iz & 255);
  x -= fx;
  y -= fy;
  z -= fz;
  const double u = Fade(x), v = Fade(y), w = Fade(z);
  const int A = p[X] + Y, AA = p[A] + Z, AB = p[A + 1] + Z;
  const int B = p[X + 1] + Y, BA = p[B] + Z, BB = p[B + 1] + Z;
  return Lerp(w,
              Lerp(v, Lerp(u, Grad(p[AA], x, y, z), Grad(p[BA], x - 1, y, z)),
                   Lerp(u, Grad(p[AB], x, y - 1, z), Grad(p[BB], x - 1, y - 1, z))),
              Lerp(v, Lerp(u, Grad(p[AA + 1], x, y, z - 1), Grad(p[BA + 1], x - 1, y, z - 1)),
                   Lerp(u, Grad(p[AB + 1], x, y - 1, z - 1), Grad(p[BB + 1], x - 1, y - 1, z - 1))));
}

double FractalNoise(const Eigen::Vector3d& p, double filter) {
  // Octaves are offset so their lattice zeros do not line up. A box filter of
  // width w scales a sinusoid of frequency f by sinc(pi w f); an octave's
  // energy sits at about 0.6 of its lattice frequency, so it is scaled by
  // sinc(0.6 pi w f) (fitted against 8x8-supersampled renders) and gone once
  // that reaches zero.
  static constexpr double kFreq[3] = {1.0, 2.03, 4.11};
  static constexpr double kAmp[3] = {1.0, 0.5, 0.25};
  static const Eigen::Vector3d kShift[3] = {{0, 0, 0}, {17.1, 3.7, 9.2}, {5.3, 29.9, 11.6}};
  double sum = 0;
  for (int k = 0; k < 3; ++k) {
    const double weight = Sinc(M_PI * 0.6 * kFreq[k] * filter);
    if (weight <= 0) break;  // finer octaves are gone too
    const Eigen::Vector3d q = kFreq[k] * p + kShift[k];
    sum += weight * kAmp[k] * PerlinNoise(q.x(), q.y(), q.z());
  }
  return sum * (1.0 / 1.75);
}

Material Material::Flat(const Eigen::Vector3f& color) {
  Material m;
  m.texture = TextureType::kFlat;
  m.color_a = m.color_b = color;
  return m;
}

Material Material::Noise(const Eigen::Vector3f& a, const Eigen::Vector3f& b, double scale) {
  Material m;
  m.texture = TextureType::kNoise;
  m.color_a = a;
  m.color_b = b;
  m.scale = scale;
  return m;
}

Material Material::Checker(const Eigen::Vector3f& a, const Eigen::Vector3f& b, double scale) {
  Material m = Noise(a, b, scale);
  m.texture = TextureType::kChecker;
  return m;
}

Material Material::Stripes(const Eigen::Vector3f& a, const Eigen::Vector3f& b, double period,
                           const Eigen::Vector3d& direction) {
  Material m = Noise(a, b, period);
  m.texture = TextureType::kStripes;
  m.direction = direction.normalized();
  return m;
}

Eigen::Vector3f Material::Albedo(const Eigen::Vector3d& p, double filter) const {
  const double w = filter / scale;  // filter width in texture units
  switch (texture) {
    case TextureType::kFlat:
      return color_a;
    case TextureType::kNoise: {
      // fBm has a standard deviation of about 0.2: a gain of 1.8 spreads it over
      // most of [0, 1] with little clipping, which gives strong gradients.
      return Mix(*this, 0.5 + 1.8 * FractalNoise(p / scale + offset, w));
    }
    case TextureType::kChecker: {
      // A smooth checker: per axis a square wave clipped from a sine, its edge
      // ramp ~1/10 of a cell wide or the filter width if that is wider (then
      // the contrast drops as a box filter's would). The offset moves the cells
      // so box faces do not sit on a cell boundary.
      const Eigen::Vector3d q = p / scale + offset;
      const double gain = 1.0 / (M_PI * std::max(0.053, 0.5 * w));
      auto wave = [gain](double x) { return std::clamp(gain * std::sin(M_PI * x), -1.0, 1.0); };
      const double parity = wave(q.x()) * wave(q.y()) * wave(q.z());
      const double n = detail > 0 ? FractalNoise(2.0 * q, 2.0 * w) : 0.0;
      return Mix(*this, 0.5 + 0.32 * parity + 1.2 * detail * n);
    }
    case TextureType::kStripes: {
      const double along = p.dot(direction) / scale;
      // One octave is enough for the slow warp of the stripes.
      const Eigen::Vector3d q = p / (2.0 * scale) + offset;
      const double warp = PerlinNoise(q.x(), q.y(), q.z());
      // A box filter of width w (in periods) scales a sinusoid by sinc(pi w).
      const double s = 0.5 + 0.5 * Sinc(M_PI * w) * std::sin(2.0 * M_PI * along + 2.0 * warp);
      const double n =
          detail > 0 ? FractalNoise(1.5 * p / scale + offset + Eigen::Vector3d(7.3, 1.9, 4.4), 1.5 * w) : 0.0;
      return Mix(*this, (1.0 - 0.5 * detail) * s + 0.25 * detail + 1.2 * detail * n);
    }
  }
  return color_a;
}

}  // namespace lfrecon::synth
