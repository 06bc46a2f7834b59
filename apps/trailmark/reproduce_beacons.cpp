// `trailmark reproduce beacons` (static part): the ultrasound-beacons paper's MDS beacon
// localization (sec. 5, Figs. 4-5) over 100 simulations per point, with shortest-path and RSSI
// completion, and the SMACOF refinement on the measured links (ours).

#include <fmt/format.h>

#include <chrono>
#include <cmath>
#include <fstream>

#include "commands.h"
#include "trailmark/beacons/mds.h"
#include "trailmark/core/random.h"

namespace trailmark::cli {

namespace fs = std::filesystem;

namespace {

/// n beacons uniform in width x height, ultrasound ranges (sigma 0.3 m) below range_m.
void RandomLayout(int n, double width, double height, double range_m, Random& rng,
                  std::vector<Vec2>* truth, beacons::RangeMatrix* m) {
  truth->clear();
  for (int i = 0; i < n; ++i) truth->emplace_back(rng.Uniform(0, width), rng.Uniform(0, height));
  m->assign(n, std::vector<std::optional<double>>(n));
  for (int i = 0; i < n; ++i) {
    for (int j = i + 1; j < n; ++j) {
      const double d = ((*truth)[i] - (*truth)[j]).norm();
      if (d < range_m) (*m)[i][j] = (*m)[j][i] = std::max(0.05, d + rng.Normal(0, 0.3));
    }
  }
}

struct MdsErrors {
  double mds = 0, refined = 0;
};

/// One simulation: n beacons uniform in 15 x 9 m, ultrasound ranges (sigma 0.3 m) between
/// beacons closer than `range_m`; the rest from shortest paths or from RSSI (n 2.3, sigma_db).
MdsErrors Simulate(int n, double range_m, bool rssi_fill, double sigma_db, Random& rng) {
  std::vector<Vec2> truth;
  beacons::RangeMatrix m;
  RandomLayout(n, 15, 9, range_m, rng, &truth, &m);
  std::vector<std::vector<double>> full;
  beacons::FillShortestPaths(m, &full);
  if (rssi_fill) {  // the missing links from RSSI (log-distance, n 2.3, alpha -40 dBm)
    for (int i = 0; i < n; ++i) {
      for (int j = i + 1; j < n; ++j) {
        if (m[i][j]) continue;
        const double d = (truth[i] - truth[j]).norm();
        const double rssi = -40 - 23 * std::log10(d) + rng.Normal(0, sigma_db);
        full[i][j] = full[j][i] = std::pow(10.0, (-40 - rssi) / 23.0);
      }
    }
  }
  const auto mds = beacons::ClassicalMds(full);
  const auto refined = beacons::RefineSmacof(m, mds);
  auto aligned = [&](const std::vector<Vec2>& est) {
    const beacons::RigidTransform T = beacons::Procrustes(est, truth);
    double s = 0;
    for (int i = 0; i < n; ++i) s += (T.Apply(est[i]) - truth[i]).norm();
    return s / n;
  };
  return {aligned(mds), aligned(refined)};
}

}  // namespace

int ReproduceBeacons(int runs, const fs::path& out) {
  std::string t = fmt::format(
      "Ultrasound-beacons paper, sec. 5 (Figs. 4-5): beacons uniform in 15 x 9 m, ultrasound "
      "ranges sigma 0.3 m within the transmission range, {} simulations per point; mean error "
      "after the best rigid alignment (Procrustes with flip) — paper: 1-3 m\n\n",
      runs);
  Random rng(1);
  auto row = [&](int n, double range, bool rssi, double sigma_db) {
    MdsErrors sum;
    for (int k = 0; k < runs; ++k) {
      const MdsErrors e = Simulate(n, range, rssi, sigma_db, rng);
      sum.mds += e.mds;
      sum.refined += e.refined;
    }
    return fmt::format("| {:.2f} m | {:.2f} m |", sum.mds / runs, sum.refined / runs);
  };
  t += "Fig. 4(a): shortest-path completion vs transmission range (21 beacons)\n\n"
       "| range | MDS | MDS + SMACOF (ours) |\n|---|---|---|\n";
  for (double r : {3.0, 4.0, 5.0, 6.0, 8.0}) t += fmt::format("| {:.0f} m ", r) + row(21, r, false, 0) + "\n";
  t += "\nFig. 4(b): shortest-path completion vs number of beacons (range 5 m)\n\n"
       "| beacons | MDS | MDS + SMACOF (ours) |\n|---|---|---|\n";
  for (int n : {10, 15, 20, 25, 30, 40}) t += fmt::format("| {} ", n) + row(n, 5.0, false, 0) + "\n";
  t += "\nFig. 5(a): RSSI completion (sigma 4 dB, n 2.3) vs transmission range (21 beacons)\n\n"
       "| range | MDS | MDS + SMACOF (ours) |\n|---|---|---|\n";
  for (double r : {3.0, 4.0, 5.0, 6.0, 8.0}) t += fmt::format("| {:.0f} m ", r) + row(21, r, true, 4.0) + "\n";
  t += "\nFig. 5(b): RSSI completion vs RSSI noise (21 beacons, range 5 m)\n\n"
       "| sigma | MDS | MDS + SMACOF (ours) |\n|---|---|---|\n";
  for (double s : {2.0, 4.0, 6.0, 8.0}) t += fmt::format("| {:.0f} dB ", s) + row(21, 5.0, true, s) + "\n";
  // 1,000 beacons: MDS + refinement time (issue 4, item 7: < 1 s).
  {
    Random big(7);
    const int n = 1000;
    std::vector<Vec2> truth;
    beacons::RangeMatrix m;
    RandomLayout(n, 150, 90, 8.0, big, &truth, &m);
    const auto t0 = std::chrono::steady_clock::now();
    std::vector<std::vector<double>> full;
    beacons::FillShortestPaths(m, &full);
    const auto mds = beacons::ClassicalMds(full);
    const auto refined = beacons::RefineSmacof(m, mds);
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const beacons::RigidTransform T = beacons::Procrustes(refined, truth);
    double err = 0;
    for (int i = 0; i < n; ++i) err += (T.Apply(refined[i]) - truth[i]).norm();
    t += fmt::format("\n1,000 beacons (150 x 90 m, 8 m range): shortest paths + MDS + SMACOF in "
                     "{:.2f} s, mean error {:.2f} m\n", s, err / n);
  }
  return WriteReproduction(out, "trailmark reproduce beacons (static localization)", t);
}

}  // namespace trailmark::cli
