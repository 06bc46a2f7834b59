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
/// No I/O.

#include <deque>
#include <optional>
#include <string>

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
  double Statistic(std::size_t begin, std::size_t end) const;
  Decision Decide(double statistic, double dt_s);

  DetectorOptions options_;
  double gamma_;
  std::deque<std::pair<Vec3, Vec3>> window_;
  std::size_t seen_ = 0;
  double swing_energy_ = 0;  ///< adaptive: tracked swing statistic
  double last_dt_ = 0.005;
};

}  // namespace trailmark::ins
