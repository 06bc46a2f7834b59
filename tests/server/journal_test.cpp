// SPDX-License-Identifier: MIT
// The incident journal: committed rows survive reopening, repeats are dropped, rows out of time
// order are refused without journaling anything, group commits, export in time order.
#include "server/journal.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <sqlite3.h>

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

TEST(Journal, AStrayTimeIsRefusedAndTheDeviceIsNotLockedOut) {
  // Issue 30: a row at t = 9.9e9 accepted live moved the incident's clock and made every later
  // row of its device "out of order".
  testing::TempDir dir;
  Journal j(dir.path() / "incident.db");
  EXPECT_EQ(j.Append(Steps("ff1", {5, 6})).accepted, 2u);
  const auto stray = j.Append(Steps("ff1", {9.9e9}));
  EXPECT_THAT(stray.error, ::testing::AllOf(::testing::HasSubstr("'ff1'"),
                                          ::testing::HasSubstr("more than a day")));
  EXPECT_EQ(stray.accepted, 0u);
  EXPECT_EQ(j.Append(Steps("ff1", {7})).accepted, 1u);  // not locked out
  // A new device's first row far from the incident's time, either way.
  EXPECT_THAT(j.Append(Steps("ff2", {9.9e9})).error, ::testing::HasSubstr("incident's latest"));
  EXPECT_THAT(j.Append(Steps("ff2", {-1e9})).error, ::testing::HasSubstr("incident's latest"));
  EXPECT_EQ(j.Append(Steps("ff2", {3})).accepted, 1u);
}

// A transaction that fails part-way (here a trigger of another connection aborts the insert of
// one row, as a full disk would fail a write) journals nothing of its group and forgets the
// times it had raised: the same rows are accepted when sent again, and a node it had seen
// first is new again.
TEST(Journal, AFailedGroupLeavesNoTraceAndItsRowsAreAcceptedLater) {
  testing::TempDir dir;
  const auto file = dir.path() / "incident.db";
  Journal j(file);
  ASSERT_EQ(j.Append(Steps("ff1", {1})).accepted, 1u);
  sqlite3* other = nullptr;
  ASSERT_EQ(sqlite3_open(file.c_str(), &other), SQLITE_OK);
  const char* trigger =
      "CREATE TRIGGER boom BEFORE INSERT ON rows WHEN NEW.node = 'ff3' "
      "BEGIN SELECT RAISE(ABORT, 'disk full (test)'); END";
  ASSERT_EQ(sqlite3_exec(other, trigger, nullptr, nullptr, nullptr), SQLITE_OK);
  const Journal::Batch ff1 = Steps("ff1", {2, 3}), ff2 = Steps("ff2", {5}), ff3 = Steps("ff3", {1});
  EXPECT_THAT([&] { j.AppendGroup({&ff1, &ff2, &ff3}); },
              ::testing::ThrowsMessage<std::runtime_error>(::testing::HasSubstr("disk full")));
  EXPECT_EQ(j.size(), 1u);
  ASSERT_EQ(sqlite3_exec(other, "DROP TRIGGER boom", nullptr, nullptr, nullptr), SQLITE_OK);
  sqlite3_close(other);
  // ff2 at t=4 would be out of order had its t=5 been kept; ff1's 2 and 3 are not duplicates.
  EXPECT_EQ(j.Append(Steps("ff2", {4})).accepted, 1u);
  const auto again = j.AppendGroup({&ff1, &ff3});
  EXPECT_EQ(again[0].accepted, 2u);
  EXPECT_EQ(again[1].accepted, 1u);
  EXPECT_EQ(j.size(), 5u);
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

/// A journal of `commits` commits of 20 steps each, closed (checkpointed into the file).
void Fill(const std::filesystem::path& file, int commits) {
  Journal j(file);
  for (int k = 0; k < commits; ++k) {
    std::vector<double> t;
    for (int i = 0; i < 20; ++i) t.push_back(2 + 20 * k + i);
    ASSERT_EQ(j.Append(Steps("ff1", t)).accepted, 20u);
  }
}

void Damage(const std::filesystem::path& file, std::size_t offset, std::size_t bytes,
            bool flip) {
  std::fstream f(file, std::ios::in | std::ios::out | std::ios::binary);
  std::string block(bytes, '\0');
  if (flip) {
    f.seekg(static_cast<std::streamoff>(offset));
    f.read(block.data(), static_cast<std::streamsize>(bytes));
    for (auto& c : block) c = static_cast<char>(~c);
  }
  f.seekp(static_cast<std::streamoff>(offset));
  f.write(block.data(), static_cast<std::streamsize>(bytes));
}

std::string OpenError(const std::filesystem::path& file) {
  try {
    Journal j(file);
  } catch (const std::runtime_error& e) {
    return e.what();
  }
  return "";
}

TEST(Journal, AZeroedPageIsRefusedAndSalvageWritesWhatIsReadable) {
  testing::TempDir dir;
  const auto file = dir.path() / "incident.db";
  Fill(file, 100);  // 2,000 rows: many pages
  ASSERT_GT(std::filesystem::file_size(file), 12 * 4096u);
  Damage(file, 8 * 4096, 4096, false);  // one page of rows zeroed
  EXPECT_THAT(OpenError(file), ::testing::HasSubstr("--salvage"));
  Journal salvage(file, Journal::Open::kSalvage);
  std::ofstream(dir.path() / "mission.json") << "{}";
  const std::size_t rows = salvage.Export(dir.path() / "out", dir.path() / "mission.json");
  EXPECT_FALSE(salvage.problems().empty());
  EXPECT_LT(rows, 2000u);
  EXPECT_GT(rows, 1000u);  // the rest is written
  EXPECT_THROW(salvage.Append(Steps("ff1", {5000})), std::runtime_error);
}

TEST(Journal, AColumnReadAsNullIsAnErrorNotAnEmptyRow) {
  // A damaged row can read as NULL; the schema's NOT NULL is taken away by hand (writable
  // schema) to make one. Reading it fails loudly, naming the column, instead of exporting "".
  testing::TempDir dir;
  const auto file = dir.path() / "incident.db";
  Fill(file, 2);
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(file.c_str(), &db), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(db,
                         "PRAGMA writable_schema = ON; UPDATE sqlite_master SET sql = "
                         "replace(sql, 'row TEXT NOT NULL', 'row TEXT') WHERE name = 'rows'; "
                         "PRAGMA writable_schema = OFF;",
                         nullptr, nullptr, nullptr),
            SQLITE_OK);
  sqlite3_close(db);
  ASSERT_EQ(sqlite3_open(file.c_str(), &db), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(db, "UPDATE rows SET row = NULL WHERE seq = 3", nullptr, nullptr, nullptr),
            SQLITE_OK);
  sqlite3_close(db);
  Journal j(file);
  EXPECT_THAT([&] { j.ForEach([](const std::string&, const std::string&, const std::string&) {}); },
              ::testing::ThrowsMessage<std::runtime_error>(
                  ::testing::HasSubstr("a row without its column 2")));
}

TEST(Journal, FlippedBytesAreRefused) {
  testing::TempDir dir;
  const auto file = dir.path() / "incident.db";
  Fill(file, 50);
  Damage(file, std::filesystem::file_size(file) / 2, 200, true);
  EXPECT_THAT(OpenError(file), ::testing::AnyOf(::testing::HasSubstr("integrity"),
                                                 ::testing::HasSubstr("damaged"),
                                                 ::testing::HasSubstr("malformed")));
}

TEST(Journal, ALostWriteAheadLogIsDetectedAtOpen) {
  testing::TempDir dir;
  const auto file = dir.path() / "incident.db";
  const auto copy = dir.path() / "copy.db";
  {
    Journal j(file);
    j.Append(Steps("ff1", {1, 2}));
    j.Append(Steps("ff1", {3, 4}));
    // What a crash that lost the write-ahead log leaves: the file without its WAL (the commits
    // are still only in incident.db-wal), with the high-water mark of what was acknowledged.
    std::filesystem::copy_file(file, copy);
    std::filesystem::copy_file(dir.path() / "incident.db.acked", dir.path() / "copy.db.acked");
  }
  const std::string why = OpenError(copy);
  EXPECT_THAT(why, ::testing::HasSubstr("holds 0 commits (0 rows) but 2 commits (4 rows) were "
                                        "acknowledged"));
  EXPECT_THAT(why, ::testing::HasSubstr("write-ahead log"));
  // The original reopens with all its rows, and counts on.
  Journal j(file);
  EXPECT_EQ(j.size(), 4u);
  j.Append(Steps("ff1", {5}));
}

TEST(Journal, ATruncatedWriteAheadLogIsDetectedAtOpen) {
  // kill -9 with the second commit's frames cut half-way in the write-ahead log (a disk that
  // lost the file's tail): SQLite recovers the first commit only; the acknowledged high-water
  // mark says two.
  testing::TempDir dir;
  const auto file = dir.path() / "incident.db";
  const auto wal = dir.path() / "incident.db-wal";
  const auto copy = dir.path() / "copy.db";
  {
    Journal j(file);
    j.Append(Steps("ff1", {1, 2}));
    const auto after_first = std::filesystem::file_size(wal);
    j.Append(Steps("ff1", {3, 4}));
    const auto after_second = std::filesystem::file_size(wal);
    ASSERT_GT(after_second, after_first);
    std::filesystem::copy_file(file, copy);
    std::filesystem::copy_file(wal, dir.path() / "copy.db-wal");
    std::filesystem::copy_file(dir.path() / "incident.db.acked", dir.path() / "copy.db.acked");
    std::filesystem::resize_file(dir.path() / "copy.db-wal",
                                 after_first + (after_second - after_first) / 2);
  }
  const std::string why = OpenError(copy);
  EXPECT_THAT(why, ::testing::HasSubstr("(2 rows) but 2 commits (4 rows) were acknowledged"));
  EXPECT_THAT(why, ::testing::HasSubstr("write-ahead log"));
}

TEST(Journal, AnEmptyOrMissingJournalIsNotANewIncident) {
  testing::TempDir dir;
  const auto file = dir.path() / "incident.db";
  Fill(file, 2);
  std::filesystem::resize_file(file, 0);
  EXPECT_THAT(OpenError(file), ::testing::HasSubstr("empty (0 bytes) but 2 commits (40 rows)"));
  std::filesystem::remove(file);
  EXPECT_THAT(OpenError(file), ::testing::HasSubstr("missing but 2 commits"));
  // Without the high-water mark it is a new incident.
  std::filesystem::remove(dir.path() / "incident.db.acked");
  EXPECT_EQ(OpenError(file), "");
  // A zero-byte file is never taken for a new incident.
  std::ofstream(dir.path() / "zero.db").close();
  EXPECT_THAT(OpenError(dir.path() / "zero.db"), ::testing::HasSubstr("empty (0 bytes)"));
}

}  // namespace
}  // namespace trailmark::server
