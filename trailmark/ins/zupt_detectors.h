// SPDX-License-Identifier: MIT
#pragma once
/// Zero-velocity (stance) detectors for a foot-mounted IMU, as evaluated by Skog, Händel,
/// Nilsson, Rantakokko, "Zero-velocity detection — an algorithm evaluation", IEEE TBME 2010
/// (eqs. numbered as there):
///   SHOE (GLRT, eq. 10): T = 1/W sum ( |a_k - g a_bar/|a_bar||^2 / sigma_a^2 + |w_k|^2 / sigma_g^2 )
///   ARE  (angular rate energy, eq. 13): T = 1/W sum |w_k|^2 / sigma_g^2
///   MV   (acceleration moving variance, eq. 11): T = 1/W sum |a_k - a_bar|^2 / sigma_a^2
///   MAG  (acceleration magnitude, eq. 12): T = 1/W sum (|a_k| - g)^2 / sigma_a^2
/// stance when T < gamma. The window of W samples is centred on the sample being classified,
/// so the decision for sample k is available W/2 samples later (Delay()).
///
/// Adaptive (beyond the paper, for crawling/walking/running/climbing): the SHOE statistic with
/// a threshold that scales with the gait: gamma_k = gamma * (E_swing / E_ref)^p where E_swing is
/// a slowly-tracked peak of the SHOE statistic over the last strides (running feet never come to
/// a full rest, so their stance statistic is higher; crawling knees and hands rest longer).
///
/// Cost: O(1) per sample. The window's sums (sum a_k, sum |a_k|^2, sum |a_k|, sum |w_k|^2) are
/// kept running (a ring of W samples, no allocation after the first window) and summed anew
/// every W samples so rounding cannot accumulate; each statistic is a closed form of them, e.g.
/// SHOE: sum |a_k - g u|^2 = sum |a_k|^2 - 2 g |sum a_k| + W g^2 with u = sum a_k / |sum a_k|.
/// `DetectorOptions::reference_arithmetic` sums every window anew instead (the reference the
/// running form is tested against). No I/O.

#include <optional>
#include <string>
#include <vector>

#include "trailmark/core/types.h"

namespace trailmark::ins {

enum class DetectorKind { kShoe, kAre, kMv, kMag, kAdaptive };
/// "shoe", "are", "mv", "mag", "adaptive"; throws std::invalid_argument otherwise.
DetectorKind ParseDetectorKind(const std::string& name);
std::string ToString(DetectorKind kind);

struct DetectorOptions {
  DetectorKind kind = DetectorKind::kAdaptive;
  int window = 5;                ///< W samples (PyShoe: 5 at 200 Hz; OpenShoe: 3 at 820 Hz)
  /// > 0: the window in seconds instead (W = max(3, round(window_s * rate)), set by the INS from
  /// the sample rate seen during alignment): one configuration across 60-820 Hz IMUs.
  double window_s = 0.05;
  /// Noise levels that normalize the statistics (Skog 2010). Defaults: PyShoe's values for a
  /// MicroStrain 3DM-GX3/GX5 (0.00098 m/s^2, 0.005 deg/s), so that gamma values compare with the
  /// literature's (PyShoe: SHOE 8.5e7 at W = 5).
  double sigma_a_mps2 = 0.00098;
  double sigma_g_radps = 8.7266463e-5;
  double gravity_mps2 = 9.8029;
  /// Threshold gamma. Defaults per kind (kShoe 8.5e7 as PyShoe's fixed-threshold run at 200 Hz;
  /// the others from Skog 2010's operating points scaled to these sigmas) via DefaultGamma().
  std::optional<double> gamma;
  // adaptive
  double adaptive_reference = 1e10;   ///< E_ref: swing SHOE energy of normal walking
  double adaptive_power = 1.0;        ///< chosen on PyShoe VICON (docs/ins.md)
  double adaptive_min_scale = 1e-3, adaptive_max_scale = 1e3;
  double adaptive_tau_s = 4.0;        ///< time constant of the swing-energy tracker
  /// Sum every window anew from its samples (O(W) per sample): the reference of the running sums.
  bool reference_arithmetic = false;
};

double DefaultGamma(DetectorKind kind);

/// Streaming detector: feed samples in order; each call returns the decision for the sample
/// Delay() samples earlier (nothing until the window is full).
class ZuptDetector {
 public:
  explicit ZuptDetector(DetectorOptions options = {});
  struct Decision {
    bool stance = false;
    double statistic = 0;
    double threshold = 0;
  };
  std::optional<Decision> Add(const Vec3& accel_b, const Vec3& gyro_b, double dt_s);
  /// Decisions for the last Delay() samples at the end of data (window shrinks).
  std::vector<Decision> Flush();
  int Delay() const { return options_.window / 2; }
  const DetectorOptions& options() const { return options_; }

 private:
  /// The statistic of the window's samples begin..end-1 (0: oldest), each term summed anew.
  double Statistic(std::size_t begin, std::size_t end) const;
  /// The statistic of the whole window from the running sums.
  double RunningStatistic() const;
  /// The statistic from a window's sums: n samples, sum a, sum |a|^2, sum |a|, sum |w|^2.
  double FromSums(double n, const Vec3& sum_a, double sum_aa, double sum_norm_a,
                  double sum_ww) const;
  void Resum();
  Decision Decide(double statistic, double dt_s);
  const std::pair<Vec3, Vec3>& At(std::size_t k) const {  // k-th oldest sample of the window
    return ring_[(head_ + k) % ring_.size()];
  }

  DetectorOptions options_;
  double gamma_;
  std::vector<std::pair<Vec3, Vec3>> ring_;  ///< W slots; the window is size_ samples from head_
  std::size_t head_ = 0, size_ = 0;
  // running sums over the window
  Vec3 sum_a_ = Vec3::Zero();
  double sum_aa_ = 0, sum_norm_a_ = 0, sum_ww_ = 0;
  std::size_t since_resum_ = 0;
  std::size_t seen_ = 0;
  double swing_energy_ = 0;  ///< adaptive: tracked swing statistic
  double last_dt_ = 0.005;
};

}  // namespace trailmark::ins
