#include "fusion/fusion_options.h"

#include <cmath>
#include <string>

#include "util/error.h"

namespace lfrecon {

void FusionOptions::Check() const {
  if (!volume.IsValid()) throw OptionError("fusion: the volume V must be a non-empty box");
  LFRECON_CHECK_OPTION(std::isfinite(voxel_size) && voxel_size > 0);
  CheckModel();
  const Eigen::Vector3d n = volume.Extent() / voxel_size;
  if (n.maxCoeff() > (1 << 20))
    throw OptionError("fusion: V is " + std::to_string(n.maxCoeff()) +
                      " voxels across at this voxel size (at most 1048576 per axis)");
}

void FusionOptions::CheckModel() const {
  LFRECON_CHECK_OPTION(std::isfinite(sigma_v) && sigma_v > 0);
  LFRECON_CHECK_OPTION(std::isfinite(sigma_s) && sigma_s > 0);
  // P(c = -1) = 1 / (1 + exp(2 / σ_s^2)) must fall below the threshold, or nothing is ever carved.
  if (1.0 / (1.0 + std::exp(2.0 / (sigma_s * sigma_s))) >= surface_threshold)
    throw OptionError("fusion: sigma_s = " + std::to_string(sigma_s) +
                      " is too large: a free-space vote P(c = -1) would not fall below the surface threshold");
  LFRECON_CHECK_OPTION(std::isfinite(band) && band > 0);
  LFRECON_CHECK_OPTION(std::isfinite(free_space_margin) && free_space_margin < band);
  LFRECON_CHECK_OPTION(probability_clamp > 0 && probability_clamp < 0.5);
  LFRECON_CHECK_OPTION(surface_threshold > 0 && surface_threshold < 1);
  LFRECON_CHECK_OPTION(activation_step > 0 && activation_step <= 2);
  LFRECON_CHECK_OPTION(activation_min_confidence >= 0 && activation_min_confidence <= 1);
  LFRECON_CHECK_OPTION(prune_every >= 0);
  LFRECON_CHECK_OPTION(prune_below > 0 && prune_below <= surface_threshold);
  LFRECON_CHECK_OPTION(store_max_block >= 1 && store_max_block <= 1024 && (store_max_block & (store_max_block - 1)) == 0);
}

Eigen::Vector3i FusionOptions::GridSize() const {
  const Eigen::Vector3d n = (volume.Extent() / voxel_size).array().ceil();
  return n.cast<int>().cwiseMax(1);
}

}  // namespace lfrecon
