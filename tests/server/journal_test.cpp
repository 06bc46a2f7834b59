// The incident journal: committed rows survive reopening, repeats are dropped, export order.
#include "server/journal.h"

#include <gtest/gtest.h>

#include <fstream>

#include "test_util.h"

namespace trailmark::server {
namespace {

TEST(Journal, CommittedRowsSurviveReopeningAndRepeatsAreDropped) {
  testing::TempDir dir;
  const auto file = dir.path() / "incident.db";
  {
    Journal j(file);
    const auto r = j.Append("steps.csv", "t0,t1,agent,dx,dy,dz,sxx,syy,szz",
                            {"0,1,ff1,1,0,0,,,", "1,2,ff1,1,0,0,,,"});
    EXPECT_EQ(r.accepted, 2u);
    EXPECT_EQ(r.duplicates, 0u);
    j.Append("rssi.csv", "t,rx,tx,rssi_dbm", {"1.5,ff1,c1,-70"});
  }  // closed as a crash would leave it: every Append had committed
  Journal j(file);
  EXPECT_EQ(j.size(), 3u);
  const auto again = j.Append("steps.csv", "t0,t1,agent,dx,dy,dz,sxx,syy,szz",
                              {"1,2,ff1,1,0,0,,,", "2,3,ff1,1,0,0,,,"});
  EXPECT_EQ(again.accepted, 1u);
  EXPECT_EQ(again.duplicates, 1u);
  // The same text in another stream is not a duplicate.
  EXPECT_EQ(j.Append("events.csv", "t,agent,event,node", {"1,2,ff1,1,0,0,,,"}).accepted, 1u);
  std::ofstream(dir.path() / "mission.json") << "{}";
  j.Export(dir.path() / "out", dir.path() / "mission.json");
  std::ifstream steps(dir.path() / "out" / "steps.csv");
  std::string all((std::istreambuf_iterator<char>(steps)), {});
  EXPECT_EQ(
      all,
      "t0,t1,agent,dx,dy,dz,sxx,syy,szz\n0,1,ff1,1,0,0,,,\n1,2,ff1,1,0,0,,,\n2,3,ff1,1,0,0,,,\n");
  EXPECT_TRUE(std::filesystem::exists(dir.path() / "out" / "mission.json"));
  EXPECT_THROW(Journal(dir.path() / "no-such-dir" / "x.db"), std::runtime_error);
}

}  // namespace
}  // namespace trailmark::server
