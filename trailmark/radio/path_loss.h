// SPDX-License-Identifier: MIT
#pragma once
/// RSSI <-> distance with the log-distance path-loss model
///   rssi = alpha - 10 n log10(d / 1 m) + X,  X ~ N(0, sigma^2) in dB
/// (breadcrumb paper sec. V; radio-landmarks paper eq. (5), whose constants have the opposite
/// sign convention: they write P = -(alpha + 10 n log10 d), i.e. alpha_paper = -alpha_here).
/// No I/O.

#include <deque>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "trailmark/core/mission.h"
#include "trailmark/core/types.h"

namespace trailmark::radio {

struct LogDistanceModel {
  double alpha_dbm = -40.0;          ///< mean RSSI at 1 m
  double path_loss_exponent = 2.3;   ///< n
  double sigma_db = 4.0;             ///< shadowing, 1 sigma
  /// Body shadowing of a body-worn radio: extra loss body_loss_db * max(0, -cos(angle between
  /// the wearer's walking direction and the direction to the other node)), i.e. full loss when
  /// the other node is straight behind (breadcrumb paper ref. [12]). 0 for static links.
  double body_loss_db = 0.0;

  static LogDistanceModel From(const RadioCalibration& c) {
    return {c.alpha_dbm, c.path_loss_exponent, c.shadowing_sigma_db};
  }
  double MeanRssi(double distance_m) const;
  /// The median distance for an RSSI value (unbiased in log-distance).
  double Distance(double rssi_dbm) const;
  /// 1-sigma of the distance at distance d from the dB noise (first order):
  /// sigma_d = d ln(10) sigma / (10 n) — distance-dependent, as the issue requires.
  double DistanceSigma(double distance_m) const;
};

struct RangeFromRssi {
  double range_m = 0;
  double sigma_m = 0;
};
RangeFromRssi ToRange(const LogDistanceModel& model, double rssi_dbm);

/// One calibration pair: a packet received at a known distance.
struct CalibrationPair {
  double distance_m = 0;
  double rssi_dbm = 0;
  double body_factor = 0;  ///< max(0, -cos(angle)) for a body-worn end, else 0
};

/// max(0, -cos) of the angle between a wearer's heading and the direction to the other node.
double BodyFactor(const Vec2& wearer, double heading_rad, const Vec2& other);

struct PathLossFit {
  LogDistanceModel model;
  double residual_sigma_db = 0;  ///< sigma of the residuals of the kept pairs
  std::size_t pairs_used = 0;
  std::size_t pairs_trimmed = 0;
};

/// Least-squares fit of alpha and n on log10(d). With trim_fraction > 0, pairs are grouped by
/// distance (bins of bin_width_m) and the trim_fraction highest and lowest RSSI of each bin are
/// dropped before the fit (radio-landmarks paper, Fig. 10: 5 %). Throws std::invalid_argument
/// with fewer than 3 pairs or fewer than 2 distinct distances.
PathLossFit FitLogDistance(const std::vector<CalibrationPair>& pairs, double trim_fraction = 0.05,
                           double bin_width_m = 0.5);
/// The same with the body-shadowing term as a third regressor (needs body factors that vary).
PathLossFit FitLogDistanceWithBody(const std::vector<CalibrationPair>& pairs,
                                   double trim_fraction = 0.05, double bin_width_m = 0.5);

/// The online calibration of the project (the breadcrumb localizer and the landmark estimator
/// use it alike): the trimmed log-distance fit, with the body-shadowing term when asked for
/// and its loss physical, accepted only when the exponent is a plausible indoor channel.
struct PathLossCalibrationOptions {
  double trim_fraction = 0.05;  ///< radio-landmarks paper, Fig. 10: 5 % each side per bin
  double bin_width_m = 1.0;     ///< m; distance bins of the trimming
  bool body_shadowing = false;  ///< also fit the body-shadowing loss (body-worn radios)
  /// Plausible indoor exponents: free space is 2, corridors guide waves down to ~1.5 and
  /// recorded 2.4 GHz BLE fits 1.3-1.8; the radio-landmarks paper measured 7.1 in its 868 MHz
  /// corridor (sec. 6.1). Outside [1.2, 8] a fit describes walls in between or pairs that do
  /// not spread in distance, not the channel (the breadcrumb localizer's bound of 1.2 and the
  /// landmark estimator's of 10 were two sets; checked on 20 office and training-building
  /// missions that neither estimator's result moves with the one set).
  double min_exponent = 1.2, max_exponent = 8.0;
  double max_body_loss_db = 20.0;  ///< dB; a body shadows 5-15 dB at 2.4 GHz
  /// dBm; the pairs are a truncated sample: packets weaker than this were never kept (a
  /// receiver's sensitivity, or a caller's own floor such as the breadcrumb localizer's
  /// min_rssi_dbm). Then the trimmed least-squares fit is only the start of a maximum-likelihood
  /// fit of the truncated normal (TruncatedPathLossFit): least squares on a truncated sample reads
  /// the missing weak packets at long range as a flat channel (exponent 1.97 where the truth
  /// was 2.8, issue 25). -inf: no truncation, the least-squares fit as it is.
  double truncation_dbm = -std::numeric_limits<double>::infinity();
  /// The likelihood fit uses at most this many pairs (an even stride over them): its cost is
  /// per pair and iteration, and 5,000 pairs fix the exponent to ~0.05.
  std::size_t max_likelihood_pairs = 5000;
  bool IsValid(std::string* why) const;
};
enum class CalibrationStatus { kOk, kNoFit, kImplausible };
struct PathLossCalibration {
  CalibrationStatus status = CalibrationStatus::kNoFit;
  PathLossFit fit;  ///< the fit (also when implausible, for the record)
  std::string why;  ///< when not kOk
};
/// The maximum-likelihood log-distance fit of a sample truncated below `truncation_dbm`: each
/// pair's RSSI is N(mu(d), sigma^2) conditioned on being >= truncation_dbm, with mu(d) = alpha -
/// 10 n log10(d) [- body_loss_db * body_factor when `body`]; alpha, n, sigma (and the body loss)
/// maximize sum log phi(z) - log sigma - log Phi((mu - c) / sigma) (the truncated regression
/// model; Ceres' L-BFGS from `start`). Pairs beyond 4 sigma of the first fit are dropped and the
/// fit repeated once (counted in pairs_trimmed). Returns false when it does not converge to a
/// finite model.
bool TruncatedPathLossFit(const std::vector<CalibrationPair>& pairs, double truncation_dbm,
                          bool body, const LogDistanceModel& start, std::size_t max_pairs,
                          PathLossFit* fit);
/// The negative log-likelihood per pair of that model and its gradient in (alpha, n, log sigma,
/// body loss) (for the test against numerical differences).
double TruncatedNegLogLikelihood(const std::vector<CalibrationPair>& pairs, double truncation_dbm,
                                 const double params[4], double gradient[4]);

/// The mean of N(mu, sigma^2) conditioned on being >= c (what a receiver that keeps only the
/// packets >= c hears on average), mu + sigma lambda(a) with a = (mu - c) / sigma and lambda the
/// inverse Mills ratio, and its derivative in mu, 1 - lambda (a + lambda) (in (0, 1): far below
/// c the kept packets no longer follow the distance). c = -inf: mu and 1.
struct TruncatedMean {
  double mean = 0;
  double d_mean_d_mu = 1;
};
TruncatedMean TruncatedNormalMean(double mu, double sigma, double c);

/// Never throws for data that cannot be fitted: the status says so (too few pairs, a single
/// distance, a degenerate body geometry, an implausible exponent).
/// With a truncation, `previous` (the last accepted fit of a growing set of pairs) starts the
/// likelihood fit instead of the least-squares one: a few iterations instead of tens.
PathLossCalibration CalibratePathLoss(const std::vector<CalibrationPair>& pairs,
                                      const PathLossCalibrationOptions& options,
                                      const LogDistanceModel* previous = nullptr);

/// Encounter detection (breadcrumb paper sec. V-A, Fig. 7; their ref. [31]): a local maximum of
/// a link's RSSI above a threshold means the agent passed within about a metre of the node.
///
/// The peak must be the strongest of the link's packets within +-half_window_s (a time, not a
/// packet count: the same passes at 1 Hz or 10 Hz). Under a channel with heavy or spatially
/// correlated shadowing a walker's approach and departure have local maxima above the threshold
/// metres away from the node (BLE at 7 dB: peaks 5-12 m out, seconds before and after the true
/// pass); within the window the strongest peak of a pass wins instead of the first.
struct EncounterOptions {
  double threshold_dbm = -40.0;  ///< paper: > -40 dB implies <= ~1 m
  /// The peak is the link's strongest packet within +- this: about 4 m of walking, where the
  /// near field's mean has fallen by 12 dB or more (n >= 2), twice the shadowing sigma of a poor
  /// indoor channel. The encounter waits this long (a latency).
  double half_window_s = 3.0;
  /// A link silent this long (its packets below the receiver's sensitivity: weaker than any
  /// peak) ends the later half window of the packets before; a peak judged only later than
  /// half_window_s + max_gap_s after it is stale and not returned.
  double max_gap_s = 3.0;
  double refractory_s = 5.0;     ///< at most one encounter per link within this time
};

class EncounterDetector {
 public:
  explicit EncounterDetector(EncounterOptions options = {}) : options_(options) {}
  /// Feeds one packet of the link (in time order); returns the time of a confirmed encounter
  /// (the peak, once half_window_s of packets after it have arrived) when there is one.
  std::optional<TimeS> Add(TimeS t, double rssi_dbm);

 private:
  EncounterOptions options_;
  std::deque<std::pair<TimeS, double>> window_;
  /// Judges window_[next_] with the packets present (missing ones are weaker).
  bool Judge();
  std::size_t next_ = 0;  ///< the oldest packet of window_ not yet judged
  TimeS last_encounter_ = -1e300;
};

/// Detects a lasting step in a static link's RSSI (a breadcrumb kicked or knocked over,
/// breadcrumb paper sec. V-C): the mean of the last `recent` packets differs from the mean of
/// everything before by more than threshold_db (after at least `reference` packets).
struct LinkChangeOptions {
  int reference = 8;
  int recent = 5;
  double threshold_db = 3.0;
  /// Also the shift's significance: |recent mean - reference mean| over the link's own packet
  /// spread (the reference window's sample sigma) times sqrt(1/recent + 1/reference) must pass
  /// this (issue 25, item 4: a fixed 3 dB on 5-packet means fired on every link whose packets
  /// spread by 6-9 dB). 0: the dB threshold alone.
  double min_z = 0.0;
};

class LinkChangeDetector {
 public:
  explicit LinkChangeDetector(LinkChangeOptions options = {}) : options_(options) {}
  /// Returns the change in dB (recent - reference) when the step is detected.
  std::optional<double> Add(double rssi_dbm);
  void Reset();
  /// recent mean - reference mean (0 until both windows are filled).
  double CurrentChange() const;
  bool Ready() const {
    return reference_count_ >= options_.reference && static_cast<int>(recent_.size()) >= options_.recent;
  }
  int packets() const { return static_cast<int>(recent_.size()) + reference_count_; }

 private:
  LinkChangeOptions options_;
  std::deque<double> recent_;
  double reference_sum_ = 0;
  double reference_sum_sq_ = 0;
  int reference_count_ = 0;
};

}  // namespace trailmark::radio
