// SPDX-License-Identifier: MIT
// `trailmark reproduce landmarks`: the radio-landmarks paper's stop-and-go experiment (sec. 6.1-
// 6.2) on simulated corridors, side by side with the paper.

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <optional>
#include <fstream>

#include "experiments/ble_flat.h"
#include "experiments/experiments.h"
#include "trailmark/eval/metrics.h"
#include "trailmark/geometry/segment.h"
#include "trailmark/io/csv.h"
#include "trailmark/ins/zupt_ins.h"
#include "trailmark/landmarks/landmark_ukf.h"
#include "trailmark/landmarks/stop_and_go.h"
#include "trailmark/sim/imu_sim.h"
#include "trailmark/sim/walker.h"
#include "trailmark/radio/path_loss.h"
#include "trailmark/sim/landmark_corridor.h"

namespace trailmark::experiments {

namespace fs = std::filesystem;

namespace {

/// Distance from a point to a polyline given as segments.
double DistanceToPath(const Vec2& p, const std::vector<Segment2>& path) {
  double best = 1e300;
  for (const Segment2& s : path) best = std::min(best, DistanceToSegment(p, s));
  return best;
}

/// The recorded BLE flat (../shared/data/ble-rss-flat): path-loss fit on the calibration
/// sessions, then single fixes (stop-and-go solver, anchors known) and UKF tracking on the
/// separate test runs. Horizontal distances throughout (the anchors' height folds into alpha).
std::string BleFlat(const fs::path& dir) {
  if (!fs::exists(dir / "anchors.csv")) return "\n(ble-rss-flat not present)\n";
  std::vector<Vec2> anchors;
  for (const Vec3& a : ReadBleFlatAnchors(dir)) anchors.push_back(a.head<2>());
  using Row = BleFlatRow;
  auto read = [&](const char* file) { return ReadBleFlatRows(dir / file, anchors.size()); };
  const auto calib = read("calibration_df.csv");
  const auto robot = read("test_robot_df.csv");
  const auto walk = read("test_walk_df.csv");
  std::vector<Segment2> path;
  {
    CsvReader r((dir / "path_reference.csv").string());
    const int a = r.RequireColumn("x0"), b = r.RequireColumn("y0"), c = r.RequireColumn("x1"), d = r.RequireColumn("y1");
    while (r.Next()) path.push_back({Vec2(r.Double(a), r.Double(b)), Vec2(r.Double(c), r.Double(d))});
  }
  std::vector<radio::CalibrationPair> pairs;
  for (const auto& row : calib) {
    for (std::size_t k = 0; k < anchors.size(); ++k) {
      if (row.rssi_dbm[k]) pairs.push_back({std::max((*row.xy - anchors[k]).norm(), 0.1), *row.rssi_dbm[k]});
    }
  }
  const radio::PathLossFit fit = radio::FitLogDistance(pairs, 0.05, 0.5);
  auto fix = [&](const Row& row) -> std::optional<Vec2> {
    landmarks::StopAndGoProblem p;
    p.landmarks = anchors;
    p.landmark_known.assign(anchors.size(), true);
    p.standing = {Vec2(4.5, 3.5)};
    p.standing_known = {false};
    std::vector<std::optional<double>> r;
    std::vector<double> s;
    int heard = 0;
    for (const auto& v : row.rssi_dbm) {
      if (v) {
        const auto range = radio::ToRange(fit.model, *v);
        r.push_back(range.range_m);
        s.push_back(std::max(range.sigma_m, 0.1));
        ++heard;
      } else {
        r.push_back(std::nullopt);
        s.push_back(1.0);
      }
    }
    if (heard < 3) return std::nullopt;
    p.range_m = {r};
    p.sigma_m = {s};
    landmarks::StopAndGoOptions o;
    o.init_grid_m = 0.2;
    o.init_margin_m = 1.0;
    return landmarks::SolveStopAndGo(p, o).standing.front();
  };
  auto track = [&](const std::vector<Row>& rows, auto&& error_of) {
    std::vector<double> fix_err, ukf_err;
    std::optional<landmarks::LandmarkUkf> ukf;
    double last_t = 0;
    for (const auto& row : rows) {
      const auto f = fix(row);
      if (f) fix_err.push_back(error_of(*f, row));
      if (!ukf) {
        if (!f) continue;
        landmarks::LandmarkUkfOptions uo;
        uo.initial_sigma_m = 2.0;
        uo.rssi_sigma_db = fit.residual_sigma_db;
        uo.tau = 0.5;
        ukf.emplace(*f, fit.model, uo);
        last_t = row.t_s;
      }
      ukf->Predict(row.t_s - last_t);
      last_t = row.t_s;
      for (std::size_t k = 0; k < anchors.size(); ++k) {
        if (row.rssi_dbm[k]) ukf->UpdateRssi(anchors[k], Mat2::Zero(), *row.rssi_dbm[k]);
      }
      ukf_err.push_back(error_of(ukf->position(), row));
    }
    return std::make_pair(Percentile(fix_err, 50), Percentile(ukf_err, 50));
  };
  const auto [robot_fix, robot_ukf] = track(robot, [](const Vec2& e, const Row& r) { return (e - *r.xy).norm(); });
  const auto [walk_fix, walk_ukf] = track(walk, [&](const Vec2& e, const Row&) { return DistanceToPath(e, path); });
  return fmt::format(
      "\nRecorded BLE RSSI in a furnished flat (ble-rss-flat, 6 anchors, Kolakowski 2021): model "
      "fitted on the calibration sessions, evaluated on the separate test runs\n\n"
      "| figure | value |\n|---|---|\n"
      "| path-loss fit on {} calibration pairs (trimmed 5 %) | n {:.2f}, alpha {:.1f} dBm, residual sigma {:.2f} dB |\n"
      "| robot test path ({} samples), median error: single fix / UKF | {:.2f} m / {:.2f} m |\n"
      "| walking test ({} samples), median distance to the walked path: single fix / UKF | {:.2f} m / {:.2f} m |\n",
      fit.pairs_used, fit.model.path_loss_exponent, fit.model.alpha_dbm, fit.residual_sigma_db,
      robot.size(), robot_fix, robot_ukf, walk.size(), walk_fix, walk_ukf);
}

/// Drift of the ZUPT INS as a random walk per metre walked (0.02-0.1 give 0.127-0.132 m here).
constexpr double kDriftPerMetre = 0.05;
}

int ReproduceLandmarks(int seeds, const fs::path& out, const fs::path& data_dir) {
  const LandmarkCorridorOptions o;
  std::vector<double> landmark_err[2], handheld_err[2];  // [squared, huber]
  std::vector<radio::CalibrationPair> pairs;
  int unsolvable = 0, degenerate = 0;
  for (int seed = 1; seed <= seeds; ++seed) {
    const LandmarkCorridor c = SimulateLandmarkCorridor(o, static_cast<std::uint64_t>(seed));
    for (std::size_t p = 0; p < c.standing.size(); ++p) {
      for (std::size_t j = 0; j < c.landmarks.size(); ++j) {
        if (c.rssi_dbm[p][j]) pairs.push_back({(c.standing[p] - c.landmarks[j]).norm(), *c.rssi_dbm[p][j]});
      }
    }
  }
  // Path-loss fit on the calibration pairs of all runs (sec. 6.1, trimmed as Fig. 10).
  const radio::PathLossFit fit = radio::FitLogDistance(pairs, 0.05, 0.5);
  // Distance-dependent sigma of the ranges from the fitted model (first order).
  for (int seed = 1; seed <= seeds; ++seed) {
    const LandmarkCorridor c = SimulateLandmarkCorridor(o, static_cast<std::uint64_t>(seed));
    for (int robust = 0; robust < 2; ++robust) {
      landmarks::StopAndGoOptions so;
      so.loss = robust ? landmarks::Loss::kHuber : landmarks::Loss::kSquared;
      landmarks::StopAndGoProblem p;
      p.landmarks.assign(c.landmarks.size(), Vec2::Zero());
      p.landmark_known.assign(c.landmarks.size(), false);
      p.standing = c.standing_from_imu;  // "assumed known, estimated by the IMU" (sec. 6.2)
      p.standing_known.assign(c.standing.size(), true);
      for (const auto& row : c.rssi_dbm) {
        std::vector<std::optional<double>> r;
        std::vector<double> s;
        for (const auto& v : row) {
          if (v) {
            const auto range = radio::ToRange(fit.model, *v);
            r.push_back(range.range_m);
            s.push_back(std::max(range.sigma_m, 0.05));
          } else {
            r.push_back(std::nullopt);
            s.push_back(1.0);
          }
        }
        p.range_m.push_back(r);
        p.sigma_m.push_back(s);
      }
      const landmarks::StopAndGoResult lr = landmarks::SolveStopAndGo(p, so);
      unsolvable += robust && !lr.solvable;
      degenerate += robust && lr.degenerate;
      for (std::size_t j = 0; j < c.landmarks.size(); ++j) {
        landmark_err[robust].push_back((lr.landmarks[j] - c.landmarks[j]).norm());
      }
      // Handheld localization without IMU: landmarks known, stops unknown (sec. 6.2).
      landmarks::StopAndGoProblem h = p;
      h.landmarks = c.landmarks;
      h.landmark_known.assign(c.landmarks.size(), true);
      h.standing_known.assign(c.standing.size(), false);
      const landmarks::StopAndGoResult hr = landmarks::SolveStopAndGo(h, so);
      for (std::size_t k = 0; k < c.standing.size(); ++k) {
        handheld_err[robust].push_back((hr.standing[k] - c.standing[k]).norm());
      }
    }
  }
  // Continuous tracking (sec. 6.3): a foot IMU at 50 Hz, wake-ups every 3 s.
  std::vector<double> err_imu, err_paper, err_ours;
  for (int seed = 1; seed <= seeds; ++seed) {
    Random rng(static_cast<std::uint64_t>(1000 + seed));
    const LandmarkCorridor c = SimulateLandmarkCorridor(o, static_cast<std::uint64_t>(seed));
    Route route;
    route.waypoints = {{0, 0}, {20, 0}, {20, 0.5}, {0, 0.5}};
    route.stops.push_back({10.0, 5.0});
    Random walk_rng = rng.Fork();
    const Walk walk = WalkRoute(route, WalkerOptions{}, 0.0, walk_rng);
    ImuSimOptions io;
    io.rate_hz = 50;
    io.grade = ImuGrade::Consumer();  // the paper's micro-IMU: ~1 m after 30 m
    const SimulatedImu imu = SimulateFootImu(walk, "ff1", io, rng.Fork());
    ins::InsOptions ino;
    ino.initial_position_n = imu.foot_truth.front().position_n;
    ins::ZuptIns ins(ino);
    std::vector<ins::InsState> states;
    ins.on_state = [&](const ins::InsState& st) { states.push_back(st); };
    for (const auto& s2 : imu.samples) ins.Add(s2);
    ins.Finish();
    landmarks::LandmarkUkfOptions uo;
    uo.initial_sigma_m = 0.05;  // the start is known (the entrance)
    const Vec2 start = imu.foot_truth.front().position_n.head<2>();
    landmarks::LandmarkUkf paper(start, fit.model, uo), ours(start, fit.model, uo);
    paper.Predict(1e-3);
    Random radio_rng = rng.Fork();
    double next_wake = 3.0;
    Vec2 last_ins = states.front().position_n.head<2>();
    for (std::size_t k = 1; k < states.size(); ++k) {
      const auto& st = states[k];
      const double dt = st.t - states[k - 1].t;
      // The paper's filter: Wiener model + acceleration (eq. 22), zeroed when still.
      paper.Predict(dt);
      if (st.stance) {
        paper.ZeroMotion();
      } else {
        const Vec3 a_n = st.q_nb * imu.samples[k].accel_b - Vec3(0, 0, ino.gravity_mps2);
        paper.UpdateAcceleration(a_n.head<2>());
      }
      // Ours: the ZUPT INS displacement as the motion model, its drift as a random walk of
      // drift_per_m of every metre walked (the EKF's own position covariance is driven by its
      // tuning noise and overstates the drift of a ZUPT INS several times).
      const Vec2 delta = st.position_n.head<2>() - last_ins;
      const double s_drift = kDriftPerMetre * delta.norm();
      ours.PredictWithDisplacement(delta, Mat2::Identity() * (s_drift * s_drift + 1e-10));
      last_ins = st.position_n.head<2>();
      if (st.t >= next_wake) {
        next_wake += 3.0;
        const Vec2 truth = imu.foot_truth[k].position_n.head<2>();
        for (const auto& l : c.landmarks) {
          const double d = std::max((truth - l).norm(), 0.1);
          double rssi = o.alpha_dbm - 10 * o.path_loss_exponent * std::log10(d) +
                        radio_rng.Normal(0, std::hypot(o.shadowing_sigma_db, o.fast_fading_sigma_db));
          if (radio_rng.Uniform(0, 1) < o.nlos_probability) rssi -= o.nlos_loss_db;
          if (rssi < o.sensitivity_dbm) continue;
          if (!st.stance) paper.UpdateRssi(l, Mat2::Zero(), rssi);  // the paper fuses only moving
          ours.UpdateRssi(l, Mat2::Zero(), rssi);
        }
      }
      if (k % 5 == 0) {  // 10 Hz evaluation
        const Vec2 truth = imu.foot_truth[k].position_n.head<2>();
        err_imu.push_back((st.position_n.head<2>() - truth).norm());
        err_paper.push_back((paper.position() - truth).norm());
        err_ours.push_back((ours.position() - truth).norm());
      }
    }
  }

  std::string t = fmt::format(
      "Radio-landmarks paper, sec. 6.1-6.2: simulated 868 MHz corridor, 5 landmarks, 7 stops, "
      "{} seeds\n\n| figure | paper | trailmark | \n|---|---|---|\n", seeds);
  t += fmt::format("| path-loss fit: n / alpha / residual sigma | 7.1 / 89.7 (their sign) / - | {:.2f} / {:.1f} dBm / {:.2f} dB (trimmed 5 %, {} pairs) |\n",
                   fit.model.path_loss_exponent, fit.model.alpha_dbm, fit.residual_sigma_db, fit.pairs_used);
  t += fmt::format("| landmark localization, median error | 0.78 m | {:.2f} m (Huber); {:.2f} m (squared loss, as the paper) |\n",
                   Percentile(landmark_err[1], 50), Percentile(landmark_err[0], 50));
  t += fmt::format("| handheld localization without IMU, median error | 0.99 m | {:.2f} m (Huber); {:.2f} m (squared) |\n",
                   Percentile(handheld_err[1], 50), Percentile(handheld_err[0], 50));
  t += fmt::format("| runs reported unsolvable / degenerate | - | {} / {} of {} |\n", unsolvable, degenerate, seeds);
  t += fmt::format("| continuous tracking, IMU only, median | 0.470 m | {:.3f} m (ZUPT INS, consumer-grade 50 Hz foot IMU) |\n",
                   Percentile(err_imu, 50));
  t += fmt::format("| continuous tracking, fused, median | 0.276 m | {:.3f} m (the paper's UKF: Wiener model + acceleration, RSSI while moving); {:.3f} m (ours: the ZUPT INS as motion model, RSSI always) |\n",
                   Percentile(err_paper, 50), Percentile(err_ours, 50));
  t += BleFlat(data_dir / "ble-rss-flat");
  return WriteReproduction(out, "trailmark reproduce landmarks", t);
}

}  // namespace trailmark::experiments
