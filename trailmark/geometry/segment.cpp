// SPDX-License-Identifier: MIT
#include "trailmark/geometry/segment.h"

#include <algorithm>
#include <cmath>
#include <vector>

namespace trailmark {
namespace {

double Cross(const Vec2& u, const Vec2& v) { return u.x() * v.y() - u.y() * v.x(); }

// Relative tolerance for orientation tests: coordinates are metres in a building, so 1e-12 of
// the squared extent is far below any physical meaning.
double Orientation(const Vec2& a, const Vec2& b, const Vec2& c) {
  const double o = Cross(b - a, c - a);
  const double scale = std::max({(b - a).squaredNorm(), (c - a).squaredNorm(), 1e-300});
  return std::abs(o) <= 1e-12 * scale ? 0.0 : o;
}

bool OnSegment(const Vec2& a, const Vec2& b, const Vec2& x) {
  return x.x() >= std::min(a.x(), b.x()) - 1e-12 && x.x() <= std::max(a.x(), b.x()) + 1e-12 &&
         x.y() >= std::min(a.y(), b.y()) - 1e-12 && x.y() <= std::max(a.y(), b.y()) + 1e-12;
}

}  // namespace

bool SegmentsIntersect(const Segment2& p, const Segment2& q) {
  const double o1 = Orientation(p.a, p.b, q.a);
  const double o2 = Orientation(p.a, p.b, q.b);
  const double o3 = Orientation(q.a, q.b, p.a);
  const double o4 = Orientation(q.a, q.b, p.b);
  if (((o1 > 0 && o2 < 0) || (o1 < 0 && o2 > 0)) && ((o3 > 0 && o4 < 0) || (o3 < 0 && o4 > 0))) {
    return true;
  }
  if (o1 == 0 && OnSegment(p.a, p.b, q.a)) return true;
  if (o2 == 0 && OnSegment(p.a, p.b, q.b)) return true;
  if (o3 == 0 && OnSegment(q.a, q.b, p.a)) return true;
  if (o4 == 0 && OnSegment(q.a, q.b, p.b)) return true;
  return false;
}

std::optional<double> FirstIntersection(const Segment2& p, const Segment2& q) {
  if (!SegmentsIntersect(p, q)) return std::nullopt;
  const Vec2 r = p.b - p.a;
  const Vec2 s = q.b - q.a;
  const double denom = Cross(r, s);
  const double rr = r.squaredNorm();
  if (std::abs(denom) > 1e-12 * std::max(rr * s.squaredNorm(), 1e-300)) {
    const double t = Cross(q.a - p.a, s) / denom;
    return std::clamp(t, 0.0, 1.0);
  }
  // Collinear (or degenerate): the first point of q's extent along p.
  if (rr <= 0.0) return 0.0;
  const double t0 = (q.a - p.a).dot(r) / rr;
  const double t1 = (q.b - p.a).dot(r) / rr;
  return std::clamp(std::min(t0, t1), 0.0, 1.0);
}

double DistanceToSegment(const Vec2& x, const Segment2& s) {
  const Vec2 d = s.b - s.a;
  const double len2 = d.squaredNorm();
  if (len2 <= 0.0) return (x - s.a).norm();
  const double t = std::clamp((x - s.a).dot(d) / len2, 0.0, 1.0);
  return (x - (s.a + t * d)).norm();
}

double PolygonArea(const std::vector<Vec2>& ring) {
  double area2 = 0.0;
  for (std::size_t i = 0; i < ring.size(); ++i) {
    area2 += Cross(ring[i], ring[(i + 1) % ring.size()]);
  }
  return 0.5 * area2;
}

bool PointInPolygon(const Vec2& x, const std::vector<Vec2>& ring) {
  bool inside = false;
  for (std::size_t i = 0, j = ring.size() - 1; i < ring.size(); j = i++) {
    const Vec2& a = ring[i];
    const Vec2& b = ring[j];
    if ((a.y() > x.y()) != (b.y() > x.y())) {
      const double xc = a.x() + (x.y() - a.y()) * (b.x() - a.x()) / (b.y() - a.y());
      if (x.x() < xc) inside = !inside;
    }
  }
  return inside;
}

}  // namespace trailmark
