// The incident journal: committed rows survive reopening, repeats are dropped, rows out of time
// order are refused without journaling anything, group commits, export in time order.
#include "server/journal.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <fstream>

#include "test_util.h"

namespace trailmark::server {
namespace {

const char* kStepsHeader = "t0,t1,agent,dx,dy,dz,sxx,syy,szz";

/// Steps of `node` ending at the times `t1` (rows "t1-1,t1,node,1,0,0,,,").
Journal::Batch Steps(const std::string& node, const std::vector<double>& t1) {
  Journal::Batch b{"steps.csv", kStepsHeader, {}, {}, {}, {}};
  for (double t : t1) {
    b.rows.push_back(std::to_string(static_cast<int>(t) - 1) + "," +
                     std::to_string(static_cast<int>(t)) + "," + node + ",1,0,0,,,");
    b.t.push_back(t);
    b.node.push_back(node);
    b.lines.push_back(b.lines.size() + 2);
  }
  return b;
}

std::string ReadFile(const std::filesystem::path& p) {
  std::ifstream in(p);
  return std::string((std::istreambuf_iterator<char>(in)), {});
}

TEST(Journal, CommittedRowsSurviveReopeningAndRepeatsAreDropped) {
  testing::TempDir dir;
  const auto file = dir.path() / "incident.db";
  {
    Journal j(file);
    const auto r = j.Append(Steps("ff1", {1, 2}));
    EXPECT_EQ(r.accepted, 2u);
    EXPECT_EQ(r.duplicates, 0u);
    EXPECT_EQ(r.fresh, (std::vector<bool>{true, true}));
    j.Append({"rssi.csv", "t,rx,tx,rssi_dbm", {"1.5,ff1,c1,-70"}, {1.5}, {"ff1"}, {2}});
  }  // closed as a crash would leave it: every Append had committed
  Journal j(file);
  EXPECT_EQ(j.size(), 3u);
  // A redelivery (row 2) is dropped even though it is older than the last accepted row.
  const auto again = j.Append(Steps("ff1", {2, 3}));
  EXPECT_EQ(again.accepted, 1u);
  EXPECT_EQ(again.duplicates, 1u);
  EXPECT_EQ(again.fresh, (std::vector<bool>{false, true}));
  // The same text in another stream is not a duplicate.
  EXPECT_EQ(j.Append({"events.csv", "t,agent,event,node", {"1,2,ff1,1,0,0,,,"}, {4}, {"ff1"}, {2}})
                .accepted,
            1u);
  std::ofstream(dir.path() / "mission.json") << "{}";
  j.Export(dir.path() / "out", dir.path() / "mission.json");
  EXPECT_EQ(ReadFile(dir.path() / "out" / "steps.csv"),
            std::string(kStepsHeader) + "\n0,1,ff1,1,0,0,,,\n1,2,ff1,1,0,0,,,\n2,3,ff1,1,0,0,,,\n");
  EXPECT_TRUE(std::filesystem::exists(dir.path() / "out" / "mission.json"));
  EXPECT_THROW(Journal(dir.path() / "no-such-dir" / "x.db"), std::runtime_error);
}

TEST(Journal, RowsOutOfTimeOrderAreRefusedAndNothingOfTheBatchIsKept) {
  testing::TempDir dir;
  Journal j(dir.path() / "incident.db");
  j.Append(Steps("ff1", {5, 6}));
  const auto r = j.Append(Steps("ff1", {7, 4, 8}));  // (a body's own order is the reader's job)
  EXPECT_THAT(r.error, ::testing::AllOf(::testing::HasSubstr("request body:3:"),
                                      ::testing::HasSubstr("'ff1'"),
                                      ::testing::HasSubstr("time order")));
  EXPECT_EQ(r.accepted, 0u);
  EXPECT_EQ(j.size(), 2u);
  // Another node's clock is independent: ff2 may send t=1 after ff1's t=6.
  EXPECT_EQ(j.Append(Steps("ff2", {1})).accepted, 1u);
  // Negative times are times like any other (a device's first row sets its clock).
  EXPECT_EQ(j.Append(Steps("ff3", {-3, -2})).accepted, 2u);
  EXPECT_EQ(j.Append(Steps("ff3", {-1})).accepted, 1u);
}

TEST(Journal, AGroupCommitsOnceAndExportsEachStreamInTimeOrder) {
  testing::TempDir dir;
  Journal j(dir.path() / "incident.db");
  const Journal::Batch a = Steps("ff2", {3, 4}), b = Steps("ff1", {1, 2}), c = Steps("ff1", {0});
  const auto results = j.AppendGroup({&a, &b, &c});
  ASSERT_EQ(results.size(), 3u);
  EXPECT_EQ(results[0].accepted, 2u);
  EXPECT_EQ(results[1].accepted, 2u);
  EXPECT_FALSE(results[2].error.empty());  // ff1's t=0 after its t=2 in the same group
  EXPECT_EQ(j.commits(), 1u);
  std::ofstream(dir.path() / "mission.json") << "{}";
  j.Export(dir.path() / "out", dir.path() / "mission.json");
  // Arrival order was ff2 (3, 4) then ff1 (1, 2); the exported file is in time order.
  EXPECT_EQ(ReadFile(dir.path() / "out" / "steps.csv"),
            std::string(kStepsHeader) +
                "\n0,1,ff1,1,0,0,,,\n1,2,ff1,1,0,0,,,\n2,3,ff2,1,0,0,,,\n3,4,ff2,1,0,0,,,\n");
}

}  // namespace
}  // namespace trailmark::server
