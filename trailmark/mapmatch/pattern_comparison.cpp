// SPDX-License-Identifier: MIT
#include "trailmark/mapmatch/pattern_comparison.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <numbers>

#include "trailmark/geometry/rigid_fit.h"
#include "trailmark/geometry/segment.h"

namespace trailmark::mapmatch {
namespace {

constexpr double kPi = std::numbers::pi;

Mat2 Rot(double a) { return Eigen::Rotation2Dd(a).toRotationMatrix(); }

// Distance of an angle to the nearest multiple of pi/2.
double ToPrincipal(double a) {
  const double q = kPi / 2;
  const double r = std::fmod(std::fmod(a, q) + q, q);  // [0, q)
  return std::min(r, q - r);
}

// The closest point of segment ab to p. The division is done only when the projection falls
// inside the segment: clamp(u / l2, 0, 1) is 0 for u <= 0 and 1 for u >= l2 in IEEE arithmetic,
// so the result is bit-identical to a + clamp(u / l2, 0, 1) * d (the ICP's inner loop).
Vec2 ClosestOnSegment(const Vec2& p, const Vec2& a, const Vec2& b) {
  const Vec2 d = b - a;
  const double l2 = d.squaredNorm();
  if (l2 <= 0) return a;
  const double u = (p - a).dot(d);
  const double t = u <= 0 ? 0.0 : (u >= l2 ? 1.0 : u / l2);
  return a + t * d;
}

// The polyline's segments in runs of kRun, each with its bounding box: a run whose box is
// farther from the query than the closest point found so far cannot hold a closer point, so the
// ICP's closest-point search skips it (segments are still visited in order, so the result is
// the plain scan's).
class ChunkedPolyline {
 public:
  static constexpr std::size_t kRun = 4;
  explicit ChunkedPolyline(const std::vector<Vec2>& line) : line_(line) {
    for (std::size_t k = 1; k < line.size(); k += kRun) {
      const std::size_t end = std::min(k + kRun, line.size());
      Box2 b;
      for (std::size_t j = k - 1; j < end; ++j) b.Extend(line[j]);
      boxes_.push_back(b);
    }
  }

  Vec2 Closest(const Vec2& p) const {
    if (line_.size() == 1) return line_[0];
    Vec2 best = line_[0];
    double best_d = 1e300;
    for (std::size_t r = 0; r < boxes_.size(); ++r) {
      // A margin far above rounding: every segment of a skipped run is strictly farther.
      if (boxes_[r].SquaredDistanceTo(p) > best_d * (1 + 1e-9) + 1e-18) continue;
      const std::size_t k0 = 1 + r * kRun, end = std::min(k0 + kRun, line_.size());
      for (std::size_t k = k0; k < end; ++k) {
        const Vec2 c = ClosestOnSegment(p, line_[k - 1], line_[k]);
        const double d = (c - p).squaredNorm();
        if (d < best_d) best_d = d, best = c;
      }
    }
    return best;
  }

 private:
  const std::vector<Vec2>& line_;
  std::vector<Box2> boxes_;
};

Vec2 Centroid(const std::vector<Vec2>& v) {
  Vec2 s = Vec2::Zero();
  for (const auto& p : v) s += p;
  return s / static_cast<double>(v.size());
}

}  // namespace

double PrincipalRotation(const std::vector<Vec2>& x) {
  std::vector<double> theta;
  for (std::size_t l = 1; l < x.size(); ++l) {
    const Vec2 d = x[l] - x[l - 1];
    if (d.squaredNorm() > 1e-12) theta.push_back(std::atan2(d.y(), d.x()));
  }
  if (theta.empty()) return 0.0;
  // C(phi) is piecewise linear in phi: its minimum is at a phi that puts one displacement
  // exactly on a principal direction.
  double best_phi = 0, best_cost = 1e300;
  for (double t : theta) {
    double phi = -t;
    phi = std::remainder(phi, kPi / 2);  // [-pi/4, pi/4]
    if (phi >= kPi / 4) phi -= kPi / 2;
    double cost = 0;
    for (double u : theta) cost += ToPrincipal(u + phi);
    if (cost < best_cost - 1e-12) best_cost = cost, best_phi = phi;
  }
  return best_phi;
}

IcpResult Icp(const std::vector<Vec2>& source, const std::vector<Vec2>& target, const Mat2& R0,
              const Vec2& t0, const IcpOptions& o) {
  IcpResult r;
  r.rotation = R0;
  r.translation = t0;
  if (source.size() < 2 || target.empty()) return r;
  const std::size_t n = source.size();
  const std::size_t keep =
      std::max<std::size_t>(2, n - static_cast<std::size_t>(o.trim_fraction * n));
  std::vector<Vec2> closest(n);
  std::vector<std::pair<double, std::size_t>> residual(n);
  std::vector<Vec2> from, to;
  const ChunkedPolyline polyline(target);
  double previous = 1e300;
  for (int it = 0; it < o.max_iterations; ++it) {
    for (std::size_t k = 0; k < n; ++k) {
      const Vec2 p = r.Apply(source[k]);
      closest[k] = polyline.Closest(p);
      residual[k] = {(closest[k] - p).squaredNorm(), k};
    }
    if (keep < n) std::nth_element(residual.begin(), residual.begin() + keep, residual.end());
    double sq = 0;
    for (std::size_t k = 0; k < keep; ++k) sq += residual[k].first;
    r.rmse_m = std::sqrt(sq / keep);
    r.iterations = it + 1;
    if (std::abs(previous - r.rmse_m) < o.tolerance_m) break;
    if ((it >= 1 && r.rmse_m > o.abandon_rmse_m) || (it == 0 && r.rmse_m > 2 * o.abandon_rmse_m))
      break;
    previous = r.rmse_m;
    from.clear();
    to.clear();
    for (std::size_t k = 0; k < keep; ++k) {
      from.push_back(source[residual[k].second]);
      to.push_back(closest[residual[k].second]);
    }
    const RigidFit2 fit = FitRigid(from, to, false);
    r.rotation = fit.rotation;
    r.translation = fit.translation;
  }
  return r;
}

bool PatternComparisonOptions::IsValid(std::string* why) const {
  if (!(pattern_length_m > 1.0) || !(point_spacing_m > 0.01) ||
      point_spacing_m > pattern_length_m / 2) {
    if (why)
      *why = "pattern_length_m must be > 1 m and point_spacing_m within 0.01 m .. half the pattern";
    return false;
  }
  return true;
}

std::vector<Vec2> ResampleByDistance(const std::vector<Vec2>& line, double spacing) {
  std::vector<Vec2> out;
  if (line.empty()) return out;
  out.push_back(line.front());
  double carry = 0;  // distance walked since the last output point
  for (std::size_t k = 1; k < line.size(); ++k) {
    const Vec2 a = line[k - 1], b = line[k];
    const double len = (b - a).norm();
    double s = spacing - carry;
    while (s <= len) {
      out.push_back(a + (b - a) * (s / len));
      s += spacing;
    }
    carry = len - (s - spacing);
  }
  if ((out.back() - line.back()).norm() > 1e-9) out.push_back(line.back());
  return out;
}

PatternComparison ComparePatterns(const std::vector<Vec2>& trajectory,
                                  const std::vector<NodeSequence>& sequences,
                                  const PatternComparisonOptions& o) {
  PatternComparison out;
  std::vector<Vec2> x = ResampleByDistance(trajectory, o.point_spacing_m);
  double length = 0;
  for (std::size_t k = 1; k < trajectory.size(); ++k)
    length += (trajectory[k] - trajectory[k - 1]).norm();
  out.principal_rotation_rad = PrincipalRotation(x);
  const Mat2 R_phi = Rot(out.principal_rotation_rad);
  for (auto& p : x) p = R_phi * p;
  const Vec2 cx = Centroid(x);
  const double inf = std::numeric_limits<double>::infinity();
  for (const NodeSequence& seq : sequences) {
    const auto& nodes = seq.nodes;
    const int N = static_cast<int>(nodes.size());
    SequenceComparison sc;
    sc.rmse_m.assign(N, {inf, inf});
    sc.position_n.assign(N, {Vec2::Zero(), Vec2::Zero()});
    sc.heading_rad.assign(N, {0.0, 0.0});
    sc.last_node.assign(N, 0);
    double total = 0;
    for (int n = 0; n < N; ++n) total += (nodes[(n + 1) % N] - nodes[n]).norm();
    if (N < 3 || x.size() < 3) {
      out.sequences.push_back(std::move(sc));
      continue;
    }
    std::vector<Vec2> pattern;
    for (int eta = 0; eta < N; ++eta) {
      // Delta N: the pattern's length as close as possible to the odometry's (cyclic).
      pattern.assign(1, nodes[eta]);
      double len = 0;
      int dn = 0;
      while (dn < N - 1) {
        const double step = (nodes[(eta + dn + 1) % N] - nodes[(eta + dn) % N]).norm();
        if (len + step > length && std::abs(len + step - length) > std::abs(len - length)) break;
        len += step;
        ++dn;
        pattern.push_back(nodes[(eta + dn) % N]);
      }
      const Vec2& first = nodes[eta];
      const Vec2& last = nodes[(eta + dn) % N];
      const Vec2 d_first = nodes[(eta + 1) % N] - nodes[eta];
      const Vec2 d_last = nodes[(eta + dn + 1) % N] - last;
      sc.position_n[eta] = {first, last};
      sc.last_node[eta] = (eta + dn) % N;
      sc.heading_rad[eta] = {std::atan2(-d_first.y(), -d_first.x()),
                             std::atan2(d_last.y(), d_last.x())};
      if (dn < 2 || total < 0.5 * length) continue;
      const Vec2 cp = Centroid(pattern);
      for (int i = 0; i < 4; ++i) {
        // The four initial rotations put the odometry's principal directions on the grid's
        // axes (the map's own axes in the paper; the walls' dominant direction in ours).
        const Mat2 Ri = Rot(seq.grid_axis_rad + i * kPi / 2);
        const IcpResult r = Icp(x, pattern, Ri, cp - Ri * cx, o.icp);
        ++out.icp_runs;
        const bool abandoned = r.rmse_m > o.icp.abandon_rmse_m;
        out.icp_abandoned += abandoned;
        (abandoned ? out.icp_iterations_abandoned : out.icp_iterations_kept) +=
            static_cast<std::size_t>(r.iterations);
        const Vec2 xk = r.Apply(x.back());
        const int end = (xk - first).norm() < (xk - last).norm() ? 0 : 1;
        sc.rmse_m[eta][end] = std::min(sc.rmse_m[eta][end], r.rmse_m);
      }
    }
    out.sequences.push_back(std::move(sc));
  }
  return out;
}

}  // namespace trailmark::mapmatch
