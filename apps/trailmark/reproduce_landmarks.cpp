// `trailmark reproduce landmarks`: the radio-landmarks paper's stop-and-go experiment (sec. 6.1-
// 6.2) on simulated corridors, side by side with the paper.

#include <fmt/format.h>

#include <fstream>

#include "commands.h"
#include "trailmark/eval/metrics.h"
#include "trailmark/landmarks/stop_and_go.h"
#include "trailmark/radio/path_loss.h"
#include "trailmark/sim/landmark_corridor.h"

namespace trailmark::cli {

namespace fs = std::filesystem;

int ReproduceLandmarks(int seeds, const fs::path& out) {
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
  fmt::print("{}", t);
  fs::create_directories(out);
  std::ofstream(out / "results.md") << "# trailmark reproduce landmarks\n\n" << t;
  fmt::print("\nwritten: {}\n", (out / "results.md").string());
  return 0;
}

}  // namespace trailmark::cli
