// SPDX-License-Identifier: MIT
#pragma once
/// Which device made the steps? A bank of landmark trackers, one per motion model, weighed by
/// how well each predicted the radio (ours, issues 21 and 24): multiple-model adaptive
/// estimation (Magill 1965; Bar-Shalom, Li & Kirubarajan 2001, sec. 11.6.2, "static MM").
///
/// The tracker's motion priors (ins/dead_reckoning.h: drift 3 deg/min, turn and step scale 3 %,
/// the steps' own heading offset 5 deg as a consider parameter) are a typical device's. A poorer
/// one (a hand-held phone, an uncalibrated gyro) is beyond them: its radio innovations are then
/// larger than the tracker says, and the estimate and its ellipse follow the wrong motion. A
/// wider prior everywhere costs accuracy where the device is a good one. The bank runs both:
///   model 0: the typical device (the tracker as configured);
///   model 1: the shared PDR error sigmas x `overbound` (the integrity guard's poor device) and
///            the steps' heading offset a state of that width instead of a consider parameter.
/// Every packet of a surveyed landmark updates both; each model's weight is multiplied by the
/// packet's predictive density under it (at the prior), so the model that explains the radio
/// better gains, and a model with more freedom is not favoured for it (its predictive densities
/// are wider: the marginal likelihood's Occam factor). Two sets of weights, from two evidences:
///   the estimate's (`weight`): the density flat beyond huber_k (an outlier is the outlier
///     process's, whatever the motion: LandmarkTracker::last_log_likelihood), so one fading dip
///     cannot hand the estimate to the freer model;
///   the ellipse's (`cover_weight`): Huber's tails up to the gate
///     (LandmarkTracker::last_huber_log_likelihood), which also count the moderate outliers a
///     poor device makes: a wider ellipse on a doubt is safe, a moved estimate is not.
/// A packet weighs once its landmark has passed the integrity monitor's window after it
/// (`evidence_delay_s`): a landmark that lies is explained best by the freer model. Weights are
/// floored at `min_weight` so a model can come back. The estimate is the typical model's until
/// the radio decides for the poor one (`prefer_typical`, the estimate's weights), its covariance
/// the mixture's mean squared error about it (each model's plus its mean's offset from the
/// estimate, the ellipse's weights). No I/O.

#include <deque>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "trailmark/landmarks/landmark_tracker.h"

namespace trailmark::landmarks {

struct TrackerBankOptions {
  /// 1: the typical device's tracker alone (the bank is that tracker, bit for bit); 2: also a
  /// poor device's.
  int models = 2;
  /// The poor device's shared PDR error sigmas, x the typical ones (3: integrity.overbound's).
  double overbound = 3.0;
  /// The poor device's heading offset (overbound x the typical one's): a state of its start
  /// heading (true) or, as the typical device's, a consider parameter (false).
  bool poor_offset_state = true;
  /// The estimate: the typical device's while its weight is at least 0.5, then moving linearly
  /// to the poor device's as that one's weight goes from 0.5 to 1 (true); or the mixture's mean
  /// (false). Either way the covariance is the mixture's mean squared error about the estimate.
  /// Where the radio cannot tell the devices apart (one surveyed landmark in a corridor) the
  /// weights stay near the prior and the mixture's mean is drawn halfway to the freer model's.
  bool prefer_typical = true;
  /// The poor device's weight before any packet (the typical one's: 1 - this).
  double poor_prior = 0.5;
  /// No model's weight falls below this (it can still take over when the device changes).
  double min_weight = 1e-3;
  /// A packet's densities weigh the models this long after it (s), and not at all when the
  /// integrity monitor excludes its landmark meanwhile: a lying landmark is best explained by
  /// the freer model, and must not choose it (the monitor's window, integrity.window_s).
  double evidence_delay_s = 20.0;
  bool IsValid(std::string* why) const;
};

class LandmarkTrackerBank {
 public:
  /// As LandmarkTracker's constructor; `bank` chooses the models. Throws std::invalid_argument
  /// for invalid options.
  LandmarkTrackerBank(const Vec3& start_n, double start_sigma_m,
                      std::optional<double> start_heading_sigma_rad,
                      const std::optional<radio::LogDistanceModel>& radio,
                      const LandmarkTrackerOptions& options, const TrackerBankOptions& bank = {});

  void AddStep(const Step& step);
  /// The typical device's motion errors replaced before the first step (the steps come from a
  /// foot INS: PdrOptions::ForFootIns); the poor device's stay (an INS may be poorer than its
  /// own model says). False once a step was added.
  bool UseTypicalMotionErrors(const PdrOptions& pdr) {
    return models_.front().UseMotionErrors(pdr);
  }
  /// A surveyed landmark's packet to every model (LandmarkTracker::UpdateRssi); the weights
  /// follow each model's predictive density of it. `admit` (the integrity monitor) is asked
  /// once, by the most probable model; the others take its verdict (and use the packet when that
  /// model gated it before asking). Returns whether the most probable model used it.
  bool UpdateRssi(TimeS t, int landmark, const Vec2& landmark_n, std::optional<double> landmark_z_m,
                  const Mat2& landmark_cov, double agent_z_m, double rssi_dbm,
                  const std::function<bool(double nis)>& admit = nullptr);
  /// An unknown landmark's packet to every model (LandmarkTracker::UpdateRssiUnknown); the
  /// weights do not move (the models place it at different times and places).
  bool UpdateRssiUnknown(TimeS t, int landmark, double dz_m, double rssi_dbm,
                         const std::function<bool(double nis)>& admit = nullptr);
  /// An unknown landmark: the mixture over the models that placed it (weights renormalized).
  std::optional<std::pair<Vec2, Mat2>> LandmarkEstimate(int landmark) const;

  /// The estimate (prefer_typical; the estimate's weights) and the mixture's mean squared error
  /// about it (each model's reported covariance plus its mean's offset from the estimate; the
  /// ellipse's weights).
  Vec2 position() const;
  Mat2 reported_position_cov() const;

  std::size_t size() const { return models_.size(); }
  const LandmarkTracker& model(std::size_t k) const { return models_.at(k); }
  /// The estimate's weight of model k (outliers flat).
  double weight(std::size_t k) const { return weights_.at(k); }
  /// The ellipse's weight of model k (outliers with Huber's tails).
  double cover_weight(std::size_t k) const { return cover_weights_.at(k); }
  /// The most probable model now.
  const LandmarkTracker& best() const { return models_[Best()]; }
  std::size_t best_index() const { return Best(); }
  /// Packets whose densities moved the weights.
  std::size_t weighed() const { return weighed_; }

 private:
  std::size_t Best() const;
  /// Bayes' rule with one packet's log-densities (one per model), then the floor.
  void Weigh(const std::vector<double>& log_likelihoods, std::vector<double>* weights) const;
  /// The last packet's densities held until evidence_delay_s passed without its landmark being
  /// excluded (`verdict`: the integrity monitor's, if it was asked); those due weigh.
  void Hold(TimeS t, int landmark, std::optional<bool> verdict);
  /// `update` on every model, the most probable first with `admit` (its verdict in `asked`);
  /// returns that one's result.
  bool ToEveryModel(
      const std::function<bool(double nis)>& admit,
      const std::function<bool(LandmarkTracker&, const std::function<bool(double)>&)>& update,
      std::optional<bool>* asked);
  struct Member {
    std::size_t model;  ///< 0: the typical device
    double weight;      ///< the estimate's; need not sum to 1 over the members
    double cover;       ///< the ellipse's; need not sum to 1 over the members
    Vec2 mean;
    Mat2 cov;
  };
  /// The estimate reported from the members (prefer_typical, else the mixture's mean; their
  /// `weight`) and the mixture's mean squared error about it (their `cover`).
  std::pair<Vec2, Mat2> Report(const std::vector<Member>& members) const;
  std::pair<Vec2, Mat2> PositionReport() const;

  std::vector<LandmarkTracker> models_;
  std::vector<double> weights_;        ///< the estimate's
  std::vector<double> cover_weights_;  ///< the ellipse's
  TrackerBankOptions bank_;
  std::size_t weighed_ = 0;
  struct Pending {
    TimeS t;
    int landmark;
    std::vector<double> log_likelihoods;        ///< the estimate's evidence, one per model
    std::vector<double> huber_log_likelihoods;  ///< the ellipse's
  };
  std::deque<Pending> pending_;
  std::map<int, bool> excluded_;  ///< the monitor's last verdict per landmark (true: excluded)
};

}  // namespace trailmark::landmarks
