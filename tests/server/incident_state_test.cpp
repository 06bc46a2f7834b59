// SPDX-License-Identifier: MIT
// The incident state behind `trailmark serve`: the /api/state contract and the alerts.
#include "server/incident_state.h"

#include <gtest/gtest.h>

#include <cmath>

namespace trailmark::server {
namespace {

MissionInfo Info() {
  MissionInfo info;
  info.nodes.push_back(NodeInfo::Agent("ff1", Vec3::Zero(), 0.1));
  info.nodes.push_back(NodeInfo::Agent("ff2", Vec3::Zero(), 0.1));
  info.nodes.push_back(NodeInfo::Base("base", Vec3::Zero()));
  return info;
}

Estimate At(const std::string& id, TimeS t, double x, double var = 0.01) {
  return {t, id, Vec3(x, 1, 0), var, 0, var};
}

TEST(IncidentState, StateJsonFollowsTheContract) {
  IncidentState s(Info());
  s.Apply(At("base", 0, 0));
  s.Apply(At("ff1", 1, 2));
  s.Apply(At("c7", 1, 3));  // a crumb dropped on the way (not declared)
  s.Advance(1.5);
  const auto j = s.ToJson();
  EXPECT_DOUBLE_EQ(j.at("t").get<double>(), 1.5);
  ASSERT_EQ(j.at("nodes").size(), 3u);
  for (const auto& n : j.at("nodes")) {
    for (const char* key : {"id", "kind", "t", "x", "y", "z", "sxx", "sxy", "syy"})
      EXPECT_TRUE(n.contains(key)) << key;
  }
  EXPECT_EQ(j.at("nodes")[1].at("id"), "c7");
  EXPECT_EQ(j.at("nodes")[1].at("kind"), "crumb");
  EXPECT_EQ(j.at("nodes")[2].at("kind"), "agent");
  EXPECT_TRUE(j.at("alerts").empty());
  // An older estimate never overwrites a newer one.
  s.Apply(At("ff1", 0.5, 9));
  EXPECT_EQ(s.stale_estimates(), 1u);
  EXPECT_DOUBLE_EQ(s.nodes().at("ff1").estimate.position_n.x(), 2);
}

// The event stream's text is written directly; it must be the document nlohmann::json builds
// from the same state (the reference below), with strings that need escaping, numbers of every
// form and a time that is not finite.
nlohmann::json ReferenceStateJson(const IncidentState& s) {
  nlohmann::json j;
  j["t"] = std::isfinite(s.now()) && s.now() > -1e299 ? nlohmann::json(s.now())
                                                      : nlohmann::json(nullptr);
  j["nodes"] = nlohmann::json::array();
  for (const auto& [id, n] : s.nodes()) {
    const Estimate& e = n.estimate;
    j["nodes"].push_back({{"id", id}, {"kind", std::string(ToString(n.kind))}, {"t", e.t},
                          {"x", e.position_n.x()}, {"y", e.position_n.y()},
                          {"z", e.position_n.z()}, {"sxx", e.sxx}, {"sxy", e.sxy},
                          {"syy", e.syy}});
  }
  j["alerts"] = nlohmann::json::array();
  for (const auto& a : s.alerts())
    j["alerts"].push_back({{"id", a.id}, {"kind", a.kind}, {"t", a.t}, {"message", a.message}});
  return j;
}

TEST(IncidentState, EventTextIsTheStateDocument) {
  IncidentState s(Info());
  EXPECT_EQ(nlohmann::json::parse(s.ToJsonText()), ReferenceStateJson(s));  // t not finite yet
  EXPECT_TRUE(nlohmann::json::parse(s.ToJsonText()).at("t").is_null());
  s.Apply(At("ff1", 1, 2));
  s.Apply({1.25, "c \"7\"\\\t\x01 \xc3\xa9", Vec3(-1e-7, 3.0e21, 123456.789), 1e300, -0.0, 5e-324});
  s.Apply(At("ff2", 2, 0.1 + 0.2, 40.0));  // a large ellipse: an uncertainty alert
  s.Advance(100.5);                         // and link lost for all
  ASSERT_FALSE(s.alerts().empty());
  const std::string text = s.ToJsonText();
  EXPECT_EQ(nlohmann::json::parse(text), ReferenceStateJson(s)) << text;
  // Numbers stay numbers of the same kind (a whole number is written as 2.0, not 2).
  EXPECT_TRUE(nlohmann::json::parse(text).at("nodes")[1].at("x").is_number_float()) << text;
}

TEST(IncidentState, TheFusionsSourcesOfAnEstimateAreInTheState) {
  IncidentState s(Info());
  s.Apply(At("ff1", 1, 2));
  s.Apply(At("ff2", 1, 3));
  s.SetSources("ff1", {{"beacons-ekf", 0.75}, {"map \"matching\"", 0.25}});
  s.Advance(1.5);
  const auto j = nlohmann::json::parse(s.ToJsonText());
  const auto& ff1 = j.at("nodes")[0];
  ASSERT_EQ(ff1.at("id"), "ff1");
  ASSERT_EQ(ff1.at("sources").size(), 2u);
  EXPECT_EQ(ff1.at("sources")[0].at("source"), "beacons-ekf");
  EXPECT_DOUBLE_EQ(ff1.at("sources")[0].at("weight").get<double>(), 0.75);
  EXPECT_EQ(ff1.at("sources")[1].at("source"), "map \"matching\"");
  EXPECT_FALSE(j.at("nodes")[1].contains("sources"));  // ff2: its estimator does not say
  s.SetSources("ff1", {});
  EXPECT_FALSE(nlohmann::json::parse(s.ToJsonText()).at("nodes")[0].contains("sources"));
}

TEST(IncidentState, AlertsForLinkLostMotionlessAndUncertainty) {
  IncidentState s(Info());
  // ff1 walks for 40 s, ff2 stands still from t = 5 s, then ff1 goes silent.
  for (int k = 0; k <= 40; ++k) {
    s.Apply(At("ff1", k, 0.5 * k));
    s.Apply(At("ff2", k, k < 5 ? k : 5.0, k > 20 ? 40.0 : 0.01));
  }
  s.Advance(40);
  auto has = [&](const std::string& id, const std::string& kind) {
    for (const auto& a : s.alerts()) {
      if (a.id == id && a.kind == kind) return true;
    }
    return false;
  };
  EXPECT_FALSE(has("ff1", "motionless"));
  EXPECT_TRUE(has("ff2", "motionless"));   // still for 35 s > 30 s
  EXPECT_TRUE(has("ff2", "uncertainty"));  // 95 % ellipse sqrt(5.991 x 40) = 15.5 m > 5 m
  EXPECT_FALSE(has("ff1", "no-data"));
  s.Advance(51);
  EXPECT_TRUE(has("ff1", "no-data"));  // 11 s without an estimate
  s.Heard("ff1", 50.5);                // an RSSI packet: the link is up, it just stands
  s.Advance(51);
  EXPECT_FALSE(has("ff1", "no-data"));
  EXPECT_NEAR(Ellipse95SemiMajor(4, 0, 1), std::sqrt(5.991 * 4), 1e-12);
}

TEST(IncidentState, MapErrorAlertWhenTheVarianceStaysHighOnAMapAidedPipeline) {
  AlertOptions o;
  o.map_error = true;  // (the default is off: only map-aided pipelines mean a map error by it)
  IncidentState s(Info(), o);
  auto active = [&](const std::string& kind) {
    for (const auto& a : s.alerts())
      if (a.id == "ff1" && a.kind == kind) return true;
    return false;
  };
  // Converged (variance 2 x 0.1 m^2), then 2 x 2 m^2 = 4 m^2 > 3 m^2 from t = 20 s.
  for (int k = 0; k <= 29; ++k) s.Apply(At("ff1", k, 0.5 * k, k >= 20 ? 2.0 : 0.1));
  s.Advance(29);
  EXPECT_FALSE(active("map-error"));  // 9 s above the level: not yet
  s.Apply(At("ff1", 30, 15, 2.0));
  s.Advance(30);
  EXPECT_TRUE(active("map-error"));  // 10 s
  s.Apply(At("ff1", 31, 15.5, 0.1));  // converged again: cleared
  s.Advance(31);
  EXPECT_FALSE(active("map-error"));
  // The same walk with the option off (pdr, say) raises no map error.
  IncidentState plain(Info());
  for (int k = 0; k <= 30; ++k) plain.Apply(At("ff1", k, 0.5 * k, k >= 20 ? 2.0 : 0.1));
  plain.Advance(30);
  for (const auto& a : plain.alerts()) EXPECT_NE(a.kind, "map-error");
  // The log holds the alert once, raised at t = 30 s.
  ASSERT_EQ(s.alert_log().size(), 1u);
  EXPECT_EQ(s.alert_log()[0].kind, "map-error");
  EXPECT_DOUBLE_EQ(s.alert_log()[0].t, 30.0);
}

TEST(IncidentState, IntegrityNotesAreAlertsFromTheirTimeUntilReadmitted) {
  IncidentState s(Info());
  s.Apply(At("ff1", 0, 0));
  s.SetIntegrity({{10, "landmark lm3", "", "excluded", "landmark lm3 excluded at t 10.0 s"},
                  {12, "agent ff1", "ff1", "disagrees", "agent ff1 at t 12.0 s: 30 m from dead reckoning"},
                  {20, "landmark lm3", "", "readmitted", "landmark lm3 readmitted at t 20.0 s"},
                  {25, "link rssi lm2->ff1", "", "repeats", "the same reading 20 times"}});
  auto kinds = [&] {
    std::vector<std::string> ids;
    for (const Alert& a : s.alerts()) {
      if (a.kind == "integrity") ids.push_back(a.id);
    }
    return ids;
  };
  s.Advance(5);
  EXPECT_TRUE(kinds().empty());  // nothing before its time
  s.Advance(13);
  EXPECT_EQ(kinds(), (std::vector<std::string>{"ff1", "landmark lm3"}));  // by source
  s.Advance(21);
  EXPECT_EQ(kinds(), (std::vector<std::string>{"ff1"}));
  s.Advance(30);
  EXPECT_EQ(kinds(), (std::vector<std::string>{"ff1", "link rssi lm2->ff1"}));
  // Each raised once in the log, with its message.
  std::size_t logged = 0;
  for (const Alert& a : s.alert_log()) logged += a.kind == "integrity";
  EXPECT_EQ(logged, 3u);
  // A later readmission of the agent clears its alert.
  s.SetIntegrity({{12, "agent ff1", "ff1", "disagrees", "x"}, {31, "agent ff1", "ff1", "agrees", "y"}});
  s.Advance(32);
  EXPECT_TRUE(kinds().empty());
}

TEST(IncidentState, AWrongSpeedOfSoundIsAnAlertOnTheAgentUntilItsRangesAgree) {
  // The beacon filter's note on an agent's ultrasound ranges (trail_estimator.h): "scale" while
  // their scale contradicts the stated speed of sound, "scale agrees" once it does not.
  IncidentState s(Info());
  s.Apply(At("ff1", 0, 0));
  s.SetIntegrity({{40, "ultrasound ranges of ff1", "ff1", "scale", "ranges read 1.120 x"},
                  {55, "ultrasound ranges of ff1", "ff1", "scale agrees", "agree again"}});
  const auto integrity = [&] {
    std::vector<std::string> out;
    for (const Alert& a : s.alerts())
      if (a.kind == "integrity") out.push_back(a.id + ": " + a.message);
    return out;
  };
  s.Advance(39);
  EXPECT_TRUE(integrity().empty());
  s.Advance(41);
  EXPECT_EQ(integrity(), (std::vector<std::string>{"ff1: ranges read 1.120 x"}));
  s.Advance(56);
  EXPECT_TRUE(integrity().empty());
}

TEST(IncidentState, HistoryKeepsTheTrailAtItsPeriodAndTheLatestEstimate) {
  IncidentState s(Info());
  for (int k = 0; k <= 40; ++k) s.Apply(At("ff1", 0.1 * k, k));  // 10 Hz for 4 s
  s.Apply(At("base", 0, 0));
  const auto h = s.HistoryJson();
  ASSERT_TRUE(h.at("trails").contains("ff1"));
  EXPECT_FALSE(h.at("trails").contains("base"));  // agents only
  const auto& rows = h.at("trails").at("ff1");
  // every 0.5 s: t = 0, 0.5, ..., 4.0 (9 rows)
  ASSERT_EQ(rows.size(), 9u);
  EXPECT_NEAR(rows[1][0].get<double>(), 0.5, 1e-9);
  EXPECT_DOUBLE_EQ(rows.back()[1].get<double>(), 40.0);
  EXPECT_EQ(h.at("columns").size(), 7u);
  EXPECT_EQ(h.at("columns").back(), "floor");
  EXPECT_TRUE(rows.back()[6].is_null());  // no floor given
  // With floors: each row carries the estimate's.
  Estimate up = At("ff1", 4.5, 41);
  up.floor = 2;
  s.Apply(up);
  const auto later = s.HistoryJson();
  EXPECT_EQ(later.at("trails").at("ff1").back()[6].get<int>(), 2);
  // Since a time: only what came after it (the dashboard's refresh).
  const auto recent = s.HistoryJson(3.2);
  const auto& tail = recent.at("trails").at("ff1");
  ASSERT_EQ(tail.size(), 3u);  // t = 3.5, 4.0 and 4.5 (the one with a floor)
  EXPECT_DOUBLE_EQ(tail.front()[0].get<double>(), 3.5);
  EXPECT_EQ(recent.at("since").get<double>(), 3.2);
  EXPECT_TRUE(s.HistoryJson(1e9).at("trails").at("ff1").empty());
}

TEST(IncidentState, AFourHourHistoryIsDecimatedToItsBudget) {
  IncidentState s(Info());
  for (int k = 0; k <= 4 * 3600 * 2; ++k) s.Apply(At("ff1", 0.5 * k, k));  // 28,801 rows
  const auto h = s.HistoryJson();
  const auto& rows = h.at("trails").at("ff1");
  ASSERT_LE(rows.size(), IncidentState::kHistoryMaxRows);
  ASSERT_GT(rows.size(), IncidentState::kHistoryMaxRows * 9 / 10);  // the stride rounds up
  EXPECT_EQ(rows.front()[0].get<double>(), 0.0);           // the start kept
  EXPECT_EQ(rows.back()[0].get<double>(), 4 * 3600.0);     // the end kept
  // The last ten minutes at the full rate, 0.5 s apart; the older rows evenly thinned.
  const std::size_t n = rows.size();
  const std::size_t recent = static_cast<std::size_t>(IncidentState::kHistoryFullRateS / 0.5);
  for (std::size_t k = n - recent; k < n; ++k) {
    ASSERT_DOUBLE_EQ(rows[k][0].get<double>() - rows[k - 1][0].get<double>(), 0.5) << k;
  }
  const int stride = h.at("decimated").at("ff1").at("stride").get<int>();
  EXPECT_EQ(stride, 16);  // ceil(27,601 older rows / 1,800 left in the budget)
  EXPECT_DOUBLE_EQ(rows[1][0].get<double>() - rows[0][0].get<double>(), 0.5 * stride);
  EXPECT_DOUBLE_EQ(h.at("decimated").at("ff1").at("full_rate_from").get<double>(),
                   4 * 3600.0 - IncidentState::kHistoryFullRateS + 0.5);
  EXPECT_EQ(n, 1 + (27601 - 1) / 16 + 1200);  // every 16th older row from the first, the recent
  // A refresh of the last minute, or a budget that holds everything: not decimated.
  const auto refresh = s.HistoryJson(4 * 3600.0 - 60);
  EXPECT_EQ(refresh.at("trails").at("ff1").size(), 120u);
  EXPECT_FALSE(refresh.contains("decimated"));
  EXPECT_EQ(s.HistoryJson(std::nullopt, 100000).at("trails").at("ff1").size(), 28801u);
}

}  // namespace
}  // namespace trailmark::server
