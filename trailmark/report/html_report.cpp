// SPDX-License-Identifier: MIT
#include "trailmark/report/html_report.h"

#include <fmt/format.h>

#include <Eigen/Eigenvalues>
#include <cmath>
#include <map>
#include <nlohmann/json.hpp>
#include <numbers>
#include <set>

#include "trailmark_generated/chartjs_bundle.h"

namespace trailmark {
namespace {

using nlohmann::json;

// One colour per pipeline, legible on the dashboard's dark map and on the white charts alike.
const char* kPalette[] = {"#ff6a3c", "#4aa8ff", "#51cf66", "#c8a2ff", "#fcc419",
                          "#22b8cf", "#f06595", "#94d82d", "#ff922b", "#adb5bd"};
// The dashboard's colours (web/dashboard/src/map.ts): walls, the truth, nodes by kind.
constexpr const char* kWallColour = "#8a93a0";
constexpr const char* kTruthColour = "#ffffff";
const char* NodeColour(NodeKind kind) {
  switch (kind) {
    case NodeKind::kBase: return "#4aa8ff";
    case NodeKind::kLandmark: return "#c8a2ff";
    default: return "#7fd17f";
  }
}

double Round3(double v) { return std::round(v * 1000.0) / 1000.0; }

json Point(const Vec2& p) { return {{"x", Round3(p.x())}, {"y", Round3(p.y())}}; }
// A break in a line (Chart.js skips points whose coordinates are null).
json Gap() { return {{"x", nullptr}, {"y", nullptr}}; }

template <class T, class F>
json Decimated(const std::vector<T>& rows, std::size_t max_points, F&& point) {
  json out = json::array();
  const std::size_t stride = rows.size() <= max_points ? 1 : (rows.size() + max_points - 1) / max_points;
  for (std::size_t i = 0; i < rows.size(); i += stride) out.push_back(point(rows[i]));
  if (!rows.empty() && (rows.size() - 1) % stride != 0) out.push_back(point(rows.back()));
  return out;
}

std::string Escape(const std::string& s) {
  std::string out;
  for (char c : s) {
    switch (c) {
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '&': out += "&amp;"; break;
      case '"': out += "&quot;"; break;
      default: out += c;
    }
  }
  return out;
}

std::string Cell(const std::optional<double>& v, int digits = 2) {
  return v ? fmt::format("{:.{}f}", *v, digits) : "&ndash;";
}

}  // namespace

std::vector<Vec2> ConfidenceEllipse(const Vec2& centre, double sxx, double sxy, double syy,
                                    int points) {
  Mat2 cov;
  cov << sxx, sxy, sxy, syy;
  Eigen::SelfAdjointEigenSolver<Mat2> eig(cov);
  const Vec2 radii = eig.eigenvalues().cwiseMax(0.0).cwiseSqrt() * std::sqrt(5.991);
  std::vector<Vec2> out;
  for (int i = 0; i <= points; ++i) {
    const double a = 2.0 * std::numbers::pi * i / points;
    out.push_back(centre + eig.eigenvectors() * Vec2(radii.x() * std::cos(a), radii.y() * std::sin(a)));
  }
  return out;
}

std::string BuildHtmlReport(const ReportInput& in) {
  Box2 box;
  json datasets = json::array();
  // Floor plan: solid walls as one dataset, segments separated by nulls.
  if (in.plan) {
    json pts = json::array();
    for (const auto& w : in.plan->solid_walls()) {
      pts.push_back(Point(w.a));
      pts.push_back(Point(w.b));
      pts.push_back(Gap());
      box.Extend(w.a);
      box.Extend(w.b);
    }
    datasets.push_back({{"label", "walls"}, {"data", pts}, {"showLine", true}, {"pointRadius", 0},
                        {"borderColor", kWallColour}, {"borderWidth", 1.5}, {"spanGaps", false}});
  }
  for (const ReportLayer& layer : in.layers) {
    if (!layer.lines.empty()) {
      json pts = json::array();
      for (const auto& line : layer.lines) {
        for (const Vec2& p : line) {
          pts.push_back(Point(p));
          box.Extend(p);
        }
        pts.push_back(Gap());
      }
      json ds = {{"label", layer.label},
                 {"data", pts},
                 {"showLine", true},
                 {"pointRadius", 0},
                 {"borderColor", layer.colour},
                 {"borderWidth", 1.5},
                 {"hidden", !layer.visible}};
      if (layer.dashed) ds["borderDash"] = json::array({4, 3});
      datasets.push_back(ds);
    }
    if (!layer.points.empty()) {
      json pts = json::array();
      for (const Vec2& p : layer.points) {
        pts.push_back(Point(p));
        box.Extend(p);
      }
      datasets.push_back({{"label", layer.lines.empty() ? layer.label : layer.label + " (points)"},
                          {"data", pts},
                          {"pointStyle", "dot"},
                          {"borderColor", layer.colour},
                          {"backgroundColor", layer.colour},
                          {"hidden", !layer.visible}});
    }
  }
  // Truth per node.
  std::map<std::string, std::vector<TruthSample>> truth_by_id;
  std::vector<std::string> ids;
  for (const auto& s : in.truth) {
    if (truth_by_id[s.id].empty()) ids.push_back(s.id);
    truth_by_id[s.id].push_back(s);
    box.Extend(s.position_n.head<2>());
  }
  auto kind_of = [&](const std::string& id) {
    const NodeInfo* n = in.info.Find(id);
    return n ? n->kind : NodeKind::kCrumb;
  };
  json static_truth = json::array();
  for (const auto& id : ids) {
    const auto& rows = truth_by_id[id];
    if (kind_of(id) == NodeKind::kAgent) {
      datasets.push_back({{"label", "truth " + id},
                          {"data", Decimated(rows, in.max_points_per_series,
                                             [](const TruthSample& s) { return Point(s.position_n.head<2>()); })},
                          {"showLine", true}, {"pointRadius", 0}, {"borderColor", kTruthColour},
                          {"borderWidth", 2}});
    } else {
      json p = Point(rows.back().position_n.head<2>());
      p["id"] = id;
      p["colour"] = NodeColour(kind_of(id));
      static_truth.push_back(p);
    }
  }
  if (!static_truth.empty()) {
    datasets.push_back({{"label", "truth crumbs/landmarks"}, {"data", static_truth},
                        {"pointStyle", "rect"}, {"pointRadius", 5}, {"borderColor", kTruthColour},
                        {"backgroundColor", kTruthColour}});
  }
  json error_sets = json::array(), cdf_sets = json::array();
  std::string table;
  for (std::size_t r = 0; r < in.runs.size(); ++r) {
    const ReportRun& run = in.runs[r];
    const std::string color = kPalette[r % std::size(kPalette)];
    std::map<std::string, std::vector<Estimate>> by_id;
    std::vector<std::string> order;
    for (const auto& e : run.estimates) {
      if (by_id[e.id].empty()) order.push_back(e.id);
      by_id[e.id].push_back(e);
      box.Extend(e.position_n.head<2>());  // show estimates that stray outside the building
    }
    json static_est = json::array();
    json ellipses = json::array();
    for (const auto& id : order) {
      const auto& rows = by_id[id];
      if (kind_of(id) == NodeKind::kAgent) {
        datasets.push_back({{"label", run.pipeline + " " + id},
                            {"data", Decimated(rows, in.max_points_per_series,
                                               [](const Estimate& e) { return Point(e.position_n.head<2>()); })},
                            {"showLine", true}, {"pointRadius", 0}, {"borderColor", color},
                            {"borderWidth", 1.5}});
        const Estimate& last = rows.back();
        for (const auto& p : ConfidenceEllipse(last.position_n.head<2>(), last.sxx, last.sxy, last.syy)) {
          ellipses.push_back(Point(p));
        }
        ellipses.push_back(Gap());
      } else if (kind_of(id) != NodeKind::kBase) {
        const Estimate& last = rows.back();
        json p = Point(last.position_n.head<2>());
        p["id"] = id;
        static_est.push_back(p);
        for (const auto& q : ConfidenceEllipse(last.position_n.head<2>(), last.sxx, last.sxy, last.syy)) {
          ellipses.push_back(Point(q));
        }
        ellipses.push_back(Gap());
      }
    }
    if (!static_est.empty()) {
      datasets.push_back({{"label", run.pipeline + " crumbs/landmarks"}, {"data", static_est},
                          {"pointStyle", "triangle"}, {"pointRadius", 6}, {"borderColor", color},
                          {"backgroundColor", color}});
    }
    if (!ellipses.empty()) {
      datasets.push_back({{"label", run.pipeline + " 95% ellipses (final)"}, {"data", ellipses},
                          {"showLine", true}, {"pointRadius", 0}, {"borderColor", color},
                          {"borderDash", {4, 3}}, {"borderWidth", 1}, {"spanGaps", false}});
    }
    const NodeMetrics& a = run.metrics.agents;
    error_sets.push_back({{"label", run.pipeline},
                          {"data", Decimated(a.series, in.max_points_per_series,
                                             [](const ErrorSample& s) { return json{{"x", Round3(s.t)}, {"y", Round3(s.error_m)}}; })},
                          {"showLine", true}, {"pointRadius", 0}, {"borderColor", color},
                          {"borderWidth", 1.5}});
    std::vector<double> errors;
    for (const auto& s : a.series) errors.push_back(s.error_m);
    std::sort(errors.begin(), errors.end());
    json cdf = json::array();
    const std::size_t n = errors.size();
    const std::size_t stride = n <= 1000 ? 1 : n / 1000;
    for (std::size_t i = 0; i < n; i += stride) {
      cdf.push_back({{"x", Round3(errors[i])}, {"y", Round3(double(i + 1) / n)}});
    }
    if (n > 0) cdf.push_back({{"x", Round3(errors.back())}, {"y", 1.0}});
    cdf_sets.push_back({{"label", run.pipeline}, {"data", cdf}, {"showLine", true},
                        {"pointRadius", 0}, {"borderColor", color}, {"borderWidth", 1.5}});
    const NodeMetrics& s = run.metrics.static_nodes;
    table += fmt::format(
        "<tr><td><span class=sw style='background:{}'></span>{}</td><td>{}</td><td>{:.2f}</td>"
        "<td>{:.2f}</td><td>{:.2f}</td><td>{:.2f}</td><td>{:.2f}</td><td>{:.2f}</td><td>{}</td>"
        "<td>{}</td><td>{}</td><td>{:.3f}</td></tr>\n",
        color, Escape(run.pipeline), a.stats.samples, a.stats.mean_m, a.stats.median_m,
        a.stats.p95_m, a.stats.max_m, a.stats.rmse_m, a.stats.final_m,
        Cell(a.mean_pct_of_distance), Cell(a.max_pct_of_distance),
        s.stats.samples > 0 ? fmt::format("{:.2f}", s.stats.mean_m) : "&ndash;", run.wall_time_s);
  }
  if (box.Empty()) {
    box.Extend(Vec2(-1, -1));
    box.Extend(Vec2(1, 1));
  }
  const Vec2 pad = Vec2::Constant(2.0);
  json map_bounds = {{"xmin", Round3(box.min.x() - pad.x())}, {"xmax", Round3(box.max.x() + pad.x())},
                     {"ymin", Round3(box.min.y() - pad.y())}, {"ymax", Round3(box.max.y() + pad.y())}};
  json data = {{"map", datasets}, {"bounds", map_bounds}, {"error", error_sets}, {"cdf", cdf_sets}};
  std::string dump = data.dump();
  // Keep "</script>" out of the embedded data.
  for (std::size_t p = 0; (p = dump.find("</", p)) != std::string::npos; p += 3) dump.replace(p, 2, "<\\/");

  std::string chartjs;
  for (auto part : generated::kChartJsParts) chartjs += part;

  std::string html;
  html += "<!doctype html>\n<html lang=en><head><meta charset=utf-8>\n";
  html += "<meta name=viewport content='width=device-width, initial-scale=1'>\n";
  html += "<title>trailmark report: " + Escape(in.info.name) + "</title>\n";
  html += R"(<style>
body{font-family:system-ui,sans-serif;margin:1.5em;color:#222;max-width:1200px}
table{border-collapse:collapse;font-size:0.9em}td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}
td:first-child,th:first-child{text-align:left}.sw{display:inline-block;width:10px;height:10px;margin-right:6px;border:1px solid #555}
.charts{display:flex;flex-wrap:wrap;gap:1em}.half{flex:1 1 480px;min-width:320px}
.note{color:#666;font-size:0.85em}
.mapwrap{position:relative;background:#101418;height:min(75vh,760px);border-radius:4px}
#map{width:100%;height:100%;touch-action:none;cursor:grab;display:block}
.mapctl{position:absolute;left:8px;top:8px;display:flex;gap:4px;align-items:center}
.mapctl button{min-width:32px;min-height:32px;font:bold 15px system-ui;background:#fff;color:#000;border:1px solid #000;border-radius:3px}
#scalebar{margin-left:8px;background:#fff;color:#000;font-size:12px;padding:1px 4px;display:flex;align-items:center;gap:4px}
#scaleline{display:inline-block;height:6px;border:2px solid #000;border-top:0}
#legend{display:flex;flex-wrap:wrap;gap:4px 14px;margin:6px 0 12px;font-size:0.9em}
</style>
)";
  html += "<script>\n";
  html += chartjs;
  html += "\n</script>\n</head><body>\n";
  html += "<h1>trailmark report &mdash; " + Escape(in.info.name) + "</h1>\n";
  html += "<p>" + Escape(in.info.description) + "</p>\n";
  html += "<h2>Metrics (agents; horizontal error, online semantics)</h2>\n";
  html += "<table><tr><th>pipeline</th><th>samples</th><th>mean m</th><th>median m</th>"
          "<th>p95 m</th><th>max m</th><th>RMSE m</th><th>final m</th><th>mean % dist</th>"
          "<th>max % dist</th><th>crumbs mean m</th><th>run time s</th></tr>\n";
  html += table + "</table>\n";
  // Floors (issue 26): where the mission is about floors.
  std::string floors;
  for (const auto& run : in.runs) {
    if (!run.metrics.floors) continue;
    const FloorMetrics& f = *run.metrics.floors;
    floors += fmt::format(
        "<tr><td>{}</td><td>{:.1f}</td><td>{:.2f}</td><td>{:.2f}</td><td>{:.2f}</td><td>{:.2f}</td>"
        "<td>{:.2f}</td></tr>\n",
        Escape(run.pipeline), 100 * f.floor_hit_rate, f.ce95_m, f.ve95_m, f.se95_m,
        f.vertical_mean_m, f.ipin_score_m);
  }
  if (!floors.empty()) {
    html += "<h2>Floors</h2><p class=note>Right floor: share of instants on the true level. CE95, "
            "VE95, SE95: 95th percentiles of the horizontal, vertical and 3-D errors (ISO/IEC "
            "18305). IPIN score: 75th percentile of horizontal error + 15 m per wrong floor.</p>\n";
    html += "<table><tr><th>pipeline</th><th>right floor %</th><th>CE95 m</th><th>VE95 m</th>"
            "<th>SE95 m</th><th>vertical mean m</th><th>IPIN score m</th></tr>\n";
    html += floors + "</table>\n";
  }
  html +=
      "<h2>Trajectories</h2><p class=note>At true scale (one metre is as long east as "
      "north). White: truth; squares: true crumbs and landmarks in the dashboard's colours; "
      "dashed: 95% ellipses of the final estimates. Wheel or +/&minus; to zoom, drag to pan, "
      "&ldquo;fit&rdquo; to see everything; tick a layer to show it (search patterns start "
      "hidden), untick to hide it.</p>\n";
  html += "<div class=mapwrap><svg id=map role=img aria-label='trajectories on the floor plan, "
          "at true scale'></svg><div class=mapctl><button type=button id=zin aria-label='zoom in'>+"
          "</button><button type=button id=zout aria-label='zoom out'>&minus;</button><button "
          "type=button id=zfit>fit</button><span id=scalebar><span id=scaleline></span><span "
          "id=scaletext></span></span></div></div>\n<div id=legend></div>\n";
  html += "<div class=charts><div class=half><h2>Error over time</h2><canvas id=err></canvas></div>"
          "<div class=half><h2>Error CDF</h2><canvas id=cdf></canvas></div></div>\n";
  html += "<p class=note>Generated by trailmark. Charts: Chart.js (MIT), embedded.</p>\n";
  html += "<script>\nconst D = " + dump + ";\n";
  html += R"(
// The map: SVG in metres (y flipped), so one metre is as long east as north at every zoom.
const b = D.bounds, NS = 'http://www.w3.org/2000/svg', svg = document.getElementById('map');
const home = [b.xmin, -b.ymax, b.xmax - b.xmin, b.ymax - b.ymin];
let vb = home.slice();
const root = document.createElementNS(NS, 'g');
root.setAttribute('transform', 'scale(1,-1)');
svg.appendChild(root);
const mark = Math.hypot(home[2], home[3]) / 250;  // marker size, m
const el = (name, attrs) => {
  const e = document.createElementNS(NS, name);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
  return e;
};
const legend = document.getElementById('legend');
D.map.forEach((ds) => {
  const g = el('g', {'data-label': ds.label});
  const stroke = {stroke: ds.borderColor, 'stroke-width': ds.borderWidth || 1.5, fill: 'none',
                  'vector-effect': 'non-scaling-stroke'};
  if (ds.borderDash) stroke['stroke-dasharray'] = ds.borderDash.join(' ');
  if (ds.showLine) {
    let pts = [];
    const flush = () => { if (pts.length > 1) g.appendChild(el('polyline', {points: pts.join(' '), ...stroke})); pts = []; };
    for (const p of ds.data) { if (p.x === null) flush(); else pts.push(p.x + ',' + p.y); }
    flush();
  } else {
    for (const p of ds.data) {
      const fill = p.colour || ds.backgroundColor || ds.borderColor;
      const shape = ds.pointStyle === 'triangle'
        ? el('polygon', {points: [[p.x, p.y + mark], [p.x - mark, p.y - mark], [p.x + mark, p.y - mark]].map((q) => q.join(',')).join(' '), fill})
        : ds.pointStyle === 'dot'
        ? el('circle', {cx: p.x, cy: p.y, r: mark * 0.35, fill})
        : el('rect', {x: p.x - mark * 0.8, y: p.y - mark * 0.8, width: mark * 1.6, height: mark * 1.6, fill});
      const title = el('title', {});
      title.textContent = (p.id ? p.id + ' ' : '') + ds.label + ' (' + p.x + ', ' + p.y + ')';
      shape.appendChild(title);
      g.appendChild(shape);
    }
  }
  root.appendChild(g);
  const label = document.createElement('label');
  const box = document.createElement('input');
  box.type = 'checkbox';
  box.checked = !ds.hidden;
  g.style.display = box.checked ? '' : 'none';
  box.onchange = () => { g.style.display = box.checked ? '' : 'none'; };
  const sw = document.createElement('span');
  sw.className = 'sw';
  sw.style.background = ds.borderColor;
  label.append(box, sw, ds.label);
  legend.appendChild(label);
});
const scaleline = document.getElementById('scaleline'), scaletext = document.getElementById('scaletext');
const setView = (v) => {
  vb = v;
  svg.setAttribute('viewBox', vb.join(' '));
  const pxPerM = svg.getScreenCTM() ? svg.getScreenCTM().a : 1;
  let len = 1;
  for (const s of [1, 2, 5, 10, 20, 50, 100, 200, 500, 1000, 2000, 5000]) if (s * pxPerM <= 120) len = s;
  scaleline.style.width = Math.round(len * pxPerM) + 'px';
  scaletext.textContent = len + ' m';
};
// Zoom by f about the point (ux, uy) of the view's coordinates.
const zoom = (f, ux, uy) => setView([ux - (ux - vb[0]) * f, uy - (uy - vb[1]) * f, vb[2] * f, vb[3] * f]);
const toView = (cx, cy) => {
  const p = svg.createSVGPoint();
  p.x = cx; p.y = cy;
  return p.matrixTransform(svg.getScreenCTM().inverse());
};
svg.addEventListener('wheel', (ev) => {
  ev.preventDefault();
  const u = toView(ev.clientX, ev.clientY);
  zoom(Math.exp(ev.deltaY * 0.0015), u.x, u.y);
}, {passive: false});
let drag = null;
svg.addEventListener('pointerdown', (ev) => { drag = {x: ev.clientX, y: ev.clientY, vb: vb.slice()}; svg.setPointerCapture(ev.pointerId); });
svg.addEventListener('pointermove', (ev) => {
  if (!drag) return;
  const a = svg.getScreenCTM().a;  // px per metre
  setView([drag.vb[0] - (ev.clientX - drag.x) / a, drag.vb[1] - (ev.clientY - drag.y) / a, drag.vb[2], drag.vb[3]]);
});
svg.addEventListener('pointerup', () => { drag = null; });
const centre = () => [vb[0] + vb[2] / 2, vb[1] + vb[3] / 2];
document.getElementById('zin').onclick = () => zoom(1 / 1.5, ...centre());
document.getElementById('zout').onclick = () => zoom(1.5, ...centre());
document.getElementById('zfit').onclick = () => setView(home.slice());
window.addEventListener('resize', () => setView(vb));
setView(home.slice());
window.trailmarkReportMap = {svg, view: () => vb.slice(), setView};
new Chart(document.getElementById('err'), {type: 'scatter', data: {datasets: D.error},
  options: {animation: false, scales: {x: {title: {display: true, text: 'time (s)'}},
    y: {min: 0, title: {display: true, text: 'horizontal error (m)'}}}}});
new Chart(document.getElementById('cdf'), {type: 'scatter', data: {datasets: D.cdf},
  options: {animation: false, scales: {x: {min: 0, title: {display: true, text: 'horizontal error (m)'}},
    y: {min: 0, max: 1, title: {display: true, text: 'fraction of time'}}}}});
</script>
</body></html>
)";
  return html;
}

}  // namespace trailmark
