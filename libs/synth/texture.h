#pragma once
// Procedural solid textures for the synthetic light-field generator. They are
// evaluated at the 3D hit point (not at a surface parameterisation), so the
// colour of a surface point is the same from every view: the brightness
// constancy the depth-from-gradient method assumes holds exactly.
#include <Eigen/Core>
#include <cstdint>
#include <string>

namespace lfrecon::synth {

enum class TextureType {
  kFlat,     // one colour: no image gradient inside the surface (textureless on purpose)
  kNoise,    // fBm of 3D gradient (Perlin) noise between two colours
  kChecker,  // 3D checkerboard (edges ramp over ~1/10 cell) with a noise overlay (`detail`)
  kStripes,  // smooth (sinusoidal) stripes along `direction`, warped by noise
};

std::string TextureTypeName(TextureType type);

struct Material {
  TextureType texture = TextureType::kNoise;
  Eigen::Vector3f color_a{0.2f, 0.2f, 0.2f};  // RGB in [0, 1]; the only colour of kFlat
  Eigen::Vector3f color_b{0.8f, 0.8f, 0.8f};  // RGB in [0, 1]
  double scale = 0.02;   // feature size in metres (noise cell, checker cell, stripe period)
  double detail = 0.35;  // noise amplitude over checker/stripes, in [0, 1]
  Eigen::Vector3d direction = Eigen::Vector3d::UnitZ();  // stripes run across this direction
  Eigen::Vector3d offset = Eigen::Vector3d::Zero();      // shifts the noise field (per-object variety)

  static Material Flat(const Eigen::Vector3f& color);
  static Material Noise(const Eigen::Vector3f& a, const Eigen::Vector3f& b, double scale);
  static Material Checker(const Eigen::Vector3f& a, const Eigen::Vector3f& b, double scale);
  static Material Stripes(const Eigen::Vector3f& a, const Eigen::Vector3f& b, double period,
                          const Eigen::Vector3d& direction);

  bool IsTextured() const { return texture != TextureType::kFlat; }
  // RGB albedo in [0, 1] at world point p, pre-filtered for a footprint of
  // `filter` metres: detail finer than the footprint fades to its mean, as a
  // box filter over the footprint would leave it (0: the exact point value).
  // A function of p and the footprint only, so it is the same from every view
  // that sees p at the same scale.
  Eigen::Vector3f Albedo(const Eigen::Vector3d& p, double filter = 0) const;
};

// Improved Perlin noise (Perlin 2002) in about [-1, 1]; a fixed permutation
// table so results are identical on every platform.
double PerlinNoise(double x, double y, double z);
// Three octaves of PerlinNoise (frequencies 1, 2.03, 4.11), about [-1, 1];
// octaves with cells under twice `filter` (in input units) fade out.
double FractalNoise(const Eigen::Vector3d& p, double filter = 0);

// Deterministic hashing / random numbers shared by the generator (splitmix64).
std::uint64_t HashCombine(std::uint64_t a, std::uint64_t b);
// Uniform double in [0, 1) from a 64-bit hash.
inline double HashToUnit(std::uint64_t h) {
  return static_cast<double>(h >> 11) * (1.0 / 9007199254740992.0);
}

}  // namespace lfrecon::synth
