// SPDX-License-Identifier: MIT
// The landmark tracker bank (tracker_bank.h) against exact references: each packet's robust
// predictive density is the Gaussian one of the EKF's innovation (a numeric Jacobian), the weights
// are Bayes' rule on those densities with their floor, the estimate is the mixture's; one model
// is the tracker itself; a device that drifts beyond the typical priors is recognized from the
// radio and its ellipse then holds the truth, a typical one keeps the typical model.
#include "trailmark/landmarks/tracker_bank.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <array>
#include <cmath>
#include <functional>

#include "landmarks/tracker_test_util.h"
#include "trailmark/core/random.h"

namespace trailmark::landmarks {
namespace {

using Vec = Eigen::VectorXd;
using Mat = Eigen::MatrixXd;
using namespace trailmark::landmarks::testing;  // NOLINT(google-build-using-namespace)

TEST(LandmarkTracker, APacketsLogLikelihoodsAreItsGaussianPredictiveDensityRobustified) {
  LandmarkTrackerOptions o;
  const Vec2 landmark(4.3, 0.6);
  const double landmark_z = 1.2;
  // Near the prediction (quadratic), beyond huber_k and beyond the gate: the estimate's evidence
  // flat beyond huber_k, the ellipse's with Huber's tails up to the gate.
  for (const double rssi : {-58.0, -40.0, -10.0}) {
    LandmarkTracker tracker(Vec3(0, 0, 0), 0.5, 0.05, radio::LogDistanceModel{-60, 2.0, 6.0}, o);
    for (int k = 0; k < 5; ++k) tracker.AddStep(MakeStep(0.5 * (k + 1), Vec2(0.7, 0)));
    EXPECT_TRUE(std::isnan(tracker.last_log_likelihood()));
    EXPECT_TRUE(std::isnan(tracker.last_huber_log_likelihood()));
    const Vec x0 = tracker.state();
    const Mat P0 = tracker.covariance();
    tracker.UpdateRssi(2.5, 7, landmark, landmark_z, Mat2::Zero(), 0.0, rssi);
    // The prior with the new link's bias state (0, 0.7 * 36), the fading 0.3 * 36.
    const int b = static_cast<int>(x0.size());
    Vec xa = Vec::Zero(b + 1);
    xa.head(b) = x0;
    Mat Pa = Mat::Zero(b + 1, b + 1);
    Pa.topLeftCorner(b, b) = P0;
    Pa(b, b) = 0.7 * 36;
    const double dz = landmark_z - o.handheld_height_m;
    const Vec H = NumericJacobian(xa, landmark, dz, b);
    const double S = H.dot(Pa * H) + 0.3 * 36;
    const double e = std::abs(rssi - Model(xa, landmark, dz, b)) / std::sqrt(S);
    const double k = o.huber_k, ek = std::min(e, k), eg = std::min(e, o.gate_sigma);
    const double log_norm = 0.5 * std::log(2 * M_PI * S);
    EXPECT_NEAR(tracker.last_log_likelihood(), -0.5 * ek * ek - log_norm, 1e-6) << rssi;
    const double rho = eg <= k ? 0.5 * eg * eg : k * eg - 0.5 * k * k;
    EXPECT_NEAR(tracker.last_huber_log_likelihood(), -rho - log_norm, 1e-6) << rssi;
  }
}

/// A square walked `laps` times around `count` surveyed landmarks, each heard at every step
/// (8 dB shadowing when `sparse`: then one landmark a step, in turn, of 4): the PDR turns
/// `turn_error` too far at every corner and drifts `drift_rad_per_s`. Calls `each(truth)` after
/// every step's packets.
template <typename Filter, typename Each>
void WalkASquare(Filter& filter, int laps, double turn_error, double drift_rad_per_s,
                 std::uint64_t seed, Each each, bool sparse = false, double offset_rad = 0) {
  Random rng(seed);
  const int count = sparse ? 4 : 8;
  const double noise_db = sparse ? 8.0 : 3.0;
  std::vector<Vec2> landmarks;
  for (int j = 0; j < count; ++j) {
    landmarks.emplace_back(5 + 8 * std::cos(j * 2 * M_PI / count),
                           5 + 8 * std::sin(j * 2 * M_PI / count));
  }
  int step = 0;
  Vec2 truth(0, 0);
  double heading = 0, pdr_heading = offset_rad;
  TimeS t = 0;
  for (int lap = 0; lap < laps; ++lap) {
    for (int side = 0; side < 4; ++side) {
      for (int k = 0; k < 14; ++k) {
        t += 0.55;
        pdr_heading += drift_rad_per_s * 0.55;
        truth += Vec2(0.7 * std::cos(heading), 0.7 * std::sin(heading));
        filter.AddStep(MakeStep(t, Vec2(0.7 * std::cos(pdr_heading), 0.7 * std::sin(pdr_heading))));
        ++step;
        for (std::size_t j = 0; j < landmarks.size(); ++j) {
          if (sparse && static_cast<int>(j) != step % count) continue;
          const double dist = std::hypot((truth - landmarks[j]).norm(), 1.5);
          filter.UpdateRssi(t, static_cast<int>(j), landmarks[j], 2.7, Mat2::Zero(), 0.0,
                            -60 - 20 * std::log10(dist) + rng.Normal(0, noise_db));
        }
        each(truth);
      }
      heading += M_PI / 2;
      pdr_heading += (1 + turn_error) * M_PI / 2;
    }
  }
}

const radio::LogDistanceModel kRadio{-60, 2.0, 4.0};

TEST(LandmarkTrackerBank, OneModelIsTheTrackerItself) {
  TrackerBankOptions one;
  one.models = 1;
  LandmarkTrackerBank bank(Vec3(0, 0, 0), 0.1, 0.02, kRadio, {}, one);
  LandmarkTracker tracker(Vec3(0, 0, 0), 0.1, 0.02, kRadio, {});
  WalkASquare(bank, 2, 0.06, 0.004, 5, [](const Vec2&) {});
  WalkASquare(tracker, 2, 0.06, 0.004, 5, [](const Vec2&) {});
  EXPECT_EQ(bank.size(), 1u);
  EXPECT_EQ(bank.position(), tracker.position());
  EXPECT_EQ(bank.reported_position_cov(), tracker.reported_position_cov());
  EXPECT_EQ(bank.weight(0), 1.0);
}

TEST(LandmarkTrackerBank,
     TheWeightsAreBayesRuleOnThePredictiveDensitiesAndTheCovarianceTheMixtures) {
  TrackerBankOptions two;
  two.evidence_delay_s = 0;  // each packet weighs at once
  LandmarkTrackerBank bank(Vec3(0, 0, 0), 0.1, 0.02, kRadio, {}, two);
  ASSERT_EQ(bank.size(), 2u);
  // The references, updated from the models' own densities: the estimate's weights (w) and the
  // ellipse's (c).
  double w0 = 0.5, w1 = 0.5, c0 = 0.5, c1 = 0.5;
  double largest_gap = 0;
  int steps = 0, poor_ahead = 0, typical_ahead = 0;
  // Each step's eight packets: the reference applies each packet's density as the bank should.
  struct Checked {
    LandmarkTrackerBank& bank;
    double& w0;
    double& w1;
    double& c0;
    double& c1;
    double& gap;
    static void Bayes(double l0, double l1, double& p0, double& p1) {
      const double top = std::max(std::log(p0) + l0, std::log(p1) + l1);
      double a = std::exp(std::log(p0) + l0 - top), b = std::exp(std::log(p1) + l1 - top);
      const double sum = a + b;
      a = std::max(a / sum, 1e-3);
      b = std::max(b / sum, 1e-3);
      p0 = a / (a + b);
      p1 = b / (a + b);
    }
    void AddStep(const Step& s) { bank.AddStep(s); }
    void UpdateRssi(TimeS t, int j, const Vec2& l, std::optional<double> z, const Mat2& c,
                    double agent_z, double rssi) {
      bank.UpdateRssi(t, j, l, z, c, agent_z, rssi);
      const LandmarkTracker &m0 = bank.model(0), &m1 = bank.model(1);
      ASSERT_TRUE(std::isfinite(m0.last_log_likelihood()) &&
                  std::isfinite(m1.last_log_likelihood()));
      Bayes(m0.last_log_likelihood(), m1.last_log_likelihood(), w0, w1);
      Bayes(m0.last_huber_log_likelihood(), m1.last_huber_log_likelihood(), c0, c1);
      gap = std::max({gap, std::abs(bank.weight(0) - w0) + std::abs(bank.weight(1) - w1),
                      std::abs(bank.cover_weight(0) - c0) + std::abs(bank.cover_weight(1) - c1)});
    }
  } checked{bank, w0, w1, c0, c1, largest_gap};
  WalkASquare(checked, 3, 0.10, 0.01, 7, [&](const Vec2&) {
    ++steps;
    // The estimate: the typical model's until the poor one's weight passes 0.5, then moving
    // linearly to the poor one's; its covariance, the mixture's mean squared error about it with
    // the ellipse's weights.
    const Vec2 x0 = bank.model(0).position(), x1 = bank.model(1).position();
    const Vec2 mean = x0 + std::max(0.0, 2 * w1 - 1) * (x1 - x0);
    const Mat2 cov =
        c0 * (bank.model(0).reported_position_cov() + (x0 - mean) * (x0 - mean).transpose()) +
        c1 * (bank.model(1).reported_position_cov() + (x1 - mean) * (x1 - mean).transpose());
    (w1 > 0.5 ? poor_ahead : typical_ahead) += 1;
    EXPECT_LT((bank.position() - mean).norm(), 1e-9);
    EXPECT_LT((bank.reported_position_cov() - cov).cwiseAbs().maxCoeff(), 1e-9);
  });
  EXPECT_EQ(steps, 3 * 4 * 14);
  EXPECT_GT(poor_ahead, 0);  // both sides of the ramp were checked
  EXPECT_GT(typical_ahead, 0);
  EXPECT_LT(largest_gap, 1e-9);
  EXPECT_EQ(bank.weighed(), static_cast<std::size_t>(steps * 8));
  EXPECT_GE(std::min(w0, w1), 1e-3 * 0.999);  // the floor held
  EXPECT_GT(std::abs(c1 - w1), 1e-3);         // the two evidences differ on this walk
}

TEST(LandmarkTrackerBank, EvidenceWeighsAfterTheMonitorsWindowAndNotFromAnExcludedLandmark) {
  // The integrity monitor (admit) excludes landmark 3 from 30 s on. The weights are Bayes' rule
  // on the packets at least 20 s older than the last, but landmark 3's still held when it was
  // excluded: the reference replays those densities.
  TrackerBankOptions delayed;
  delayed.evidence_delay_s = 20;
  LandmarkTrackerBank bank(Vec3(0, 0, 0), 0.1, 0.02, kRadio, {}, delayed);
  struct Packet {
    TimeS t;
    int landmark;
    double l0, l1;
  };
  std::vector<Packet> packets;
  bool lied = false;
  struct Feed {
    LandmarkTrackerBank& bank;
    std::vector<Packet>& packets;
    bool& lied;
    void AddStep(const Step& s) { bank.AddStep(s); }
    void UpdateRssi(TimeS t, int j, const Vec2& l, std::optional<double> z, const Mat2& c,
                    double agent_z, double rssi) {
      const bool refused = j == 3 && t >= 30;
      lied = lied || refused;
      bank.UpdateRssi(t, j, l, z, c, agent_z, rssi, [&](double) { return !refused; });
      packets.push_back(
          {t, j, bank.model(0).last_log_likelihood(), bank.model(1).last_log_likelihood()});
    }
  } feed{bank, packets, lied};
  WalkASquare(feed, 2, 0.03, 0.002, 3, [](const Vec2&) {});
  ASSERT_TRUE(lied);
  // No packet gated: the monitor was asked about each (the reference below needs that).
  ASSERT_EQ(bank.model(0).gated() + bank.model(1).gated(), 0u);
  // A packet counts once a later one is 20 s after it; landmark 3's held when the monitor
  // first refused it (at its first packet from 30 s on) are dropped.
  const TimeS end = packets.back().t;
  TimeS before_exclusion = 0;
  for (std::size_t k = 1; k < packets.size(); ++k) {
    if (packets[k].landmark == 3 && packets[k].t >= 30) {
      before_exclusion = packets[k - 1].t;
      break;
    }
  }
  double w0 = 0.5, w1 = 0.5;
  std::size_t counted = 0;
  for (const Packet& p : packets) {
    if (p.t > end - 20) continue;                                  // too recent
    if (p.landmark == 3 && p.t > before_exclusion - 20) continue;  // held, then dropped
    const double top = std::max(std::log(w0) + p.l0, std::log(w1) + p.l1);
    double a = std::exp(std::log(w0) + p.l0 - top), b = std::exp(std::log(w1) + p.l1 - top);
    const double sum = a + b;
    a = std::max(a / sum, 1e-3);
    b = std::max(b / sum, 1e-3);
    w0 = a / (a + b);
    w1 = b / (a + b);
    ++counted;
  }
  EXPECT_EQ(bank.weighed(), counted);
  EXPECT_NEAR(bank.weight(0), w0, 1e-12);
  EXPECT_NEAR(bank.weight(1), w1, 1e-12);
  EXPECT_LT(counted, packets.size() * 9 / 10);  // the lie's and the last 20 s's left out
}

/// The share of steps (after the first lap) whose truth lies in the filter's 95 % ellipse.
template <typename Filter>
double In95(Filter& filter, double turn_error, double drift_rad_per_s, std::uint64_t seed,
            double offset_rad = 0) {
  int inside = 0, counted = 0, step = 0;
  WalkASquare(
      filter, 4, turn_error, drift_rad_per_s, seed,
      [&](const Vec2& truth) {
        if (++step <= 56) return;
        const Vec2 e = filter.position() - truth;
        inside += e.dot(filter.reported_position_cov().ldlt().solve(e)) <= 5.991;
        ++counted;
      },
      true, offset_rad);
  return static_cast<double>(inside) / counted;
}

TEST(LandmarkTrackerBank, ADeviceBeyondTheTypicalPriorsIsRecognizedFromTheRadio) {
  // Sparse, noisy radio (4 landmarks, one packet a step, 8 dB). A poor device: its steps point
  // 17 deg off the stated start heading (a phone's carrying mode; the typical offset is 5 deg),
  // drift 15 deg/min (5 times the typical sigma) and turn 8 % too far (2.7 sigma).
  const double offset = 0.3, drift = 15 * M_PI / 180 / 60, turn = 0.08;
  TrackerBankOptions at_once;  // the evidence's delay is tested above
  at_once.evidence_delay_s = 0;
  // The ellipse's weights (Huber's tails) recognize it on every seed; the estimate's (outliers
  // flat) on two of the three: on seed 13 the typical model's innovations are mostly beyond
  // huber_k, where that evidence no longer tells the models apart, and the estimate stays the
  // typical one's (weight 0.15) while the ellipse covers the poor one's.
  double bank_sum = 0;
  int estimate_recognized = 0;
  for (const std::uint64_t seed : {11u, 12u, 13u}) {
    LandmarkTrackerBank bank(Vec3(0, 0, 0), 0.1, 0.02, kRadio, {}, at_once);
    LandmarkTracker typical(Vec3(0, 0, 0), 0.1, 0.02, kRadio, {});
    const double bank_in95 = In95(bank, turn, drift, seed, offset);
    const double typical_in95 = In95(typical, turn, drift, seed, offset);
    EXPECT_GT(bank.cover_weight(1), 0.9) << seed;
    estimate_recognized += bank.weight(1) > 0.9;
    EXPECT_GT(bank_in95, typical_in95 + 0.2) << seed;
    bank_sum += bank_in95;
  }
  EXPECT_GE(estimate_recognized, 2);
  EXPECT_GT(bank_sum / 3, 0.75);
  // A typical device (no offset or drift, 1 % turn scale) keeps the typical model, and an
  // ellipse as honest as the typical tracker's.
  for (const std::uint64_t seed : {11u, 12u, 13u}) {
    LandmarkTrackerBank bank(Vec3(0, 0, 0), 0.1, 0.02, kRadio, {}, at_once);
    LandmarkTracker typical(Vec3(0, 0, 0), 0.1, 0.02, kRadio, {});
    const double bank_in95 = In95(bank, 0.01, 0.0, seed);
    const double typical_in95 = In95(typical, 0.01, 0.0, seed);
    EXPECT_GT(bank.weight(0), 0.5) << seed;
    EXPECT_GT(bank.cover_weight(0), 0.5) << seed;
    EXPECT_GE(bank_in95, typical_in95 - 0.02) << seed;
  }
}

TEST(LandmarkTrackerBank, AnOutliersEvidenceIsTheSameHoweverFarOutItIs) {
  // A packet the filter takes for an outlier (beyond huber_k) is the outlier process's, whatever
  // the motion: its density, and so the models' weights, must not depend on how far out it is.
  // With Huber's linear tails as the evidence, a fading dip 3-4 sigma out moved the weights by
  // (e1 - e0) * huber_k nats towards the model with the wider prediction, and one such packet
  // handed a corridor walk to the poor model (docs/landmarks.md). After a walk (3 dB radio, the
  // predictions' sigma ~2.5 dB), the bank's last packet again, dipped by 6, 8 or 10 dB (beyond
  // huber_k and within the gate under both models), and, for contrast, by 1 and 2 dB (inliers).
  TrackerBankOptions at_once;
  at_once.evidence_delay_s = 0;
  struct Feed {
    LandmarkTrackerBank bank;
    std::function<void(LandmarkTrackerBank&, double)> last;  // the last packet, dipped
    void AddStep(const Step& s) { bank.AddStep(s); }
    void UpdateRssi(TimeS t, int j, const Vec2& l, std::optional<double> z, const Mat2& c,
                    double agent_z, double rssi) {
      bank.UpdateRssi(t, j, l, z, c, agent_z, rssi);
      last = [=](LandmarkTrackerBank& b, double dip_db) {
        b.UpdateRssi(t, j, l, z, c, agent_z, rssi - dip_db);
      };
    }
  } feed{LandmarkTrackerBank(Vec3(0, 0, 0), 0.1, 0.02, kRadio, {}, at_once), nullptr};
  WalkASquare(feed, 1, 0.03, 0.002, 9, [](const Vec2&) {});
  auto dipped = [&](double dip_db) {
    LandmarkTrackerBank b = feed.bank;
    feed.last(b, dip_db);
    return std::array<double, 3>{b.model(0).last_log_likelihood(), b.model(1).last_log_likelihood(),
                                 b.weight(1)};
  };
  const auto at6 = dipped(6), at8 = dipped(8), at10 = dipped(10);
  for (int k = 0; k < 3; ++k) {
    EXPECT_EQ(at6[k], at8[k]) << k;
    EXPECT_EQ(at6[k], at10[k]) << k;
  }
  const auto at1 = dipped(1), at2 = dipped(2);
  EXPECT_GT(std::abs(at1[0] - at2[0]), 1e-3);  // within huber_k the density does depend on it
  EXPECT_GT(at2[0], at6[0]);
}

TEST(LandmarkTrackerBank, ThePoorDeviceIsTheOverboundedPriorsWithItsOffsetEstimated) {
  LandmarkTrackerOptions typical;
  TrackerBankOptions b;
  b.poor_prior = 0.3;
  const double stated = 0.02, offset = 3 * typical.pdr.track_heading_offset_sigma_rad;
  const LandmarkTrackerBank bank(Vec3(0, 0, 0), 0.1, stated, kRadio, typical, b);
  EXPECT_DOUBLE_EQ(bank.weight(1), 0.3);
  const Mat& P0 = bank.model(0).covariance();
  const Mat& P1 = bank.model(1).covariance();
  using T = LandmarkTracker;
  EXPECT_DOUBLE_EQ(P0(T::kHeading, T::kHeading), stated * stated);
  EXPECT_NEAR(P1(T::kHeading, T::kHeading), stated * stated + offset * offset, 1e-15);
  EXPECT_NEAR(P1(T::kRate, T::kRate), 9 * P0(T::kRate, T::kRate), 1e-18);
  EXPECT_NEAR(P1(T::kScale, T::kScale), 9 * P0(T::kScale, T::kScale), 1e-15);
  EXPECT_NEAR(P1(T::kTurnScale, T::kTurnScale), 9 * P0(T::kTurnScale, T::kTurnScale), 1e-15);
  // Its offset is a state: nothing left to report beside it (the typical one's is considered).
  EXPECT_EQ(bank.model(1).reported_position_cov(), bank.model(1).position_cov());
  // As a consider parameter instead: the stated heading, and three times the typical offset
  // reported.
  b.poor_offset_state = false;
  const LandmarkTrackerBank considered(Vec3(0, 0, 0), 0.1, stated, kRadio, typical, b);
  EXPECT_DOUBLE_EQ(considered.model(1).covariance()(T::kHeading, T::kHeading), stated * stated);
}

TEST(LandmarkTrackerBank, RefusesInvalidOptions) {
  for (const auto& change : std::vector<std::function<void(TrackerBankOptions&)>>{
           [](TrackerBankOptions& b) { b.models = 0; }, [](TrackerBankOptions& b) { b.models = 3; },
           [](TrackerBankOptions& b) { b.overbound = 0.5; },
           [](TrackerBankOptions& b) { b.overbound = std::nan(""); },
           [](TrackerBankOptions& b) { b.min_weight = 0; },
           [](TrackerBankOptions& b) { b.poor_prior = 0; },
           [](TrackerBankOptions& b) { b.poor_prior = 1; },
           [](TrackerBankOptions& b) { b.min_weight = 0.5; },
           [](TrackerBankOptions& b) { b.evidence_delay_s = -1; }}) {
    TrackerBankOptions b;
    change(b);
    EXPECT_FALSE(b.IsValid(nullptr));
    EXPECT_THROW(LandmarkTrackerBank(Vec3(0, 0, 0), 0.1, 0.02, kRadio, {}, b),
                 std::invalid_argument);
  }
}

}  // namespace
}  // namespace trailmark::landmarks
