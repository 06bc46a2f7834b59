// SPDX-License-Identifier: MIT
#include "trailmark/report/html_report.h"

#include <gtest/gtest.h>

#include <map>
#include <nlohmann/json.hpp>

namespace trailmark {
namespace {

TEST(ConfidenceEllipse, AxesFollowTheCovariance) {
  // sxx = 4, syy = 1: semi-axes 2*sqrt(5.991) along x and sqrt(5.991) along y.
  const auto pts = ConfidenceEllipse({1, 1}, 4, 0, 1, 4);
  double max_x = 0, max_y = 0;
  for (const auto& p : pts) {
    max_x = std::max(max_x, std::abs(p.x() - 1));
    max_y = std::max(max_y, std::abs(p.y() - 1));
  }
  EXPECT_NEAR(max_x, 2 * std::sqrt(5.991), 1e-9);
  EXPECT_NEAR(max_y, std::sqrt(5.991), 1e-9);
}

TEST(HtmlReport, IsSelfContained) {
  ReportInput in;
  in.info.name = "t<1>";
  in.truth = {{0, "ff1", Vec3(0, 0, 0)}, {1, "ff1", Vec3(1, 0, 0)}};
  in.info.nodes.push_back({.id = "ff1", .kind = NodeKind::kAgent});
  ReportRun run;
  run.pipeline = "pdr";
  run.estimates = {{0, "ff1", Vec3(0, 0, 0), 1, 0, 1}};
  run.metrics = Evaluate(in.info, in.truth, run.estimates);
  in.runs.push_back(run);
  const std::string html = BuildHtmlReport(in);
  EXPECT_NE(html.find("t&lt;1&gt;"), std::string::npos);      // escaped
  EXPECT_NE(html.find("new Chart("), std::string::npos);
  EXPECT_NE(html.find("Chart.js v4"), std::string::npos);      // library embedded
  EXPECT_EQ(html.find("src=\"http"), std::string::npos);       // nothing fetched
  EXPECT_EQ(html.find("https://cdn"), std::string::npos);
  EXPECT_EQ(html.find("<h2>Floors</h2>"), std::string::npos);  // a single-floor mission
}

TEST(HtmlReport, FloorsTableWhereTheMissionIsAboutFloors) {
  ReportInput in;
  in.info.name = "two floors";
  in.info.floors = {{0, 0.0}, {1, 3.5}};
  in.info.nodes.push_back({.id = "ff1", .kind = NodeKind::kAgent});
  in.truth = {{0, "ff1", Vec3(0, 0, 0), 0}, {1, "ff1", Vec3(0, 0, 3.5), 1}};
  ReportRun run;
  run.pipeline = "pdr";
  // On level 0 throughout: right half of the time, one wrong floor at t = 1.
  run.estimates = {{0, "ff1", Vec3(0, 0, 0), 1, 0, 1, 0.01, 0}};
  run.metrics = Evaluate(in.info, in.truth, run.estimates);
  ASSERT_TRUE(run.metrics.floors);
  EXPECT_DOUBLE_EQ(run.metrics.floors->floor_hit_rate, 0.5);
  EXPECT_DOUBLE_EQ(run.metrics.floors->ve95_m, 0.95 * 3.5);  // numpy's linear percentile
  in.runs.push_back(run);
  const std::string html = BuildHtmlReport(in);
  EXPECT_NE(html.find("<h2>Floors</h2>"), std::string::npos);
  EXPECT_NE(html.find("<td>pdr</td><td>50.0</td>"), std::string::npos);
}

TEST(HtmlReport, LineBreaksAreNullPointsNotNullEntries) {
  // Chart.js crashes on a bare null in object-parsed scatter data (seen in a browser).
  ReportInput in;
  in.plan = FloorPlan({{{0, 0}, {1, 0}}, {{0, 1}, {1, 1}}}, {}, {});
  in.info.nodes.push_back({.id = "c1", .kind = NodeKind::kCrumb});
  ReportRun run;
  run.pipeline = "x";
  run.estimates = {{0, "c1", Vec3(0, 0, 0), 1, 0, 1}};
  in.runs.push_back(run);
  const std::string html = BuildHtmlReport(in);
  const auto data_at = html.find("const D = ");
  ASSERT_NE(data_at, std::string::npos);
  const std::string data = html.substr(data_at);  // our data, not the embedded library
  EXPECT_EQ(data.find(",null"), std::string::npos);
  EXPECT_EQ(data.find("[null"), std::string::npos);
  EXPECT_NE(data.find(R"({"x":null,"y":null})"), std::string::npos);
}

// Extra layers (map matching's search patterns): each a map dataset with its label, colour,
// lines broken by null points and its points, hidden until ticked unless visible; the map's
// bounds take them in.
TEST(HtmlReport, LayersAreMapDatasetsHiddenUntilTicked) {
  ReportInput in;
  in.info.nodes.push_back({.id = "ff1", .kind = NodeKind::kAgent});
  in.truth = {{0, "ff1", Vec3(0, 0, 0)}, {1, "ff1", Vec3(1, 0, 0)}};
  ReportLayer sequences;
  sequences.label = "search sequences";
  sequences.colour = "#2e8b57";
  sequences.lines = {{{0, 0}, {0, 5}}, {{1, 1}, {2, 1}}};
  sequences.points = {{7, -3}};
  ReportLayer doors;
  doors.label = "doors no search sequence passes (1)";
  doors.lines = {{{3, 3}, {3, 4}}};
  doors.dashed = true;
  doors.visible = true;
  in.layers = {sequences, doors};
  const std::string html = BuildHtmlReport(in);
  const std::string data = html.substr(html.find("const D = "));
  const auto json_end = data.find(";\n");
  const auto d = nlohmann::json::parse(data.substr(10, json_end - 10));
  std::map<std::string, nlohmann::json> by_label;
  for (const auto& ds : d["map"]) by_label[ds["label"].get<std::string>()] = ds;
  ASSERT_TRUE(by_label.count("search sequences"));
  ASSERT_TRUE(by_label.count("search sequences (points)"));
  ASSERT_TRUE(by_label.count("doors no search sequence passes (1)"));
  const auto& lines = by_label["search sequences"];
  EXPECT_EQ(lines["hidden"], true);
  EXPECT_EQ(lines["borderColor"], "#2e8b57");
  EXPECT_EQ(lines["data"].size(), 6u);  // two lines of two points, each closed by a null point
  EXPECT_TRUE(lines["data"][2]["x"].is_null());
  EXPECT_EQ(by_label["search sequences (points)"]["pointStyle"], "dot");
  EXPECT_EQ(by_label["doors no search sequence passes (1)"]["hidden"], false);
  EXPECT_TRUE(by_label["doors no search sequence passes (1)"].contains("borderDash"));
  EXPECT_LE(d["bounds"]["xmin"].get<double>(), 0.0);
  EXPECT_GE(d["bounds"]["xmax"].get<double>(), 7.0);
  EXPECT_LE(d["bounds"]["ymin"].get<double>(), -3.0);
  EXPECT_GE(d["bounds"]["ymax"].get<double>(), 5.0);
}

}  // namespace
}  // namespace trailmark
