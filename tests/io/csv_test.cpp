// SPDX-License-Identifier: MIT
// Every reader rejects bad input with file, line and problem; good input in any column order.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "test_util.h"
#include "trailmark/core/error.h"
#include "trailmark/io/streams.h"
#include "trailmark/sim/synthetic_streams.h"

namespace trailmark {
namespace {

using ::testing::AllOf;
using ::testing::HasSubstr;
using testing::TempDir;

// Reads all rows and returns the error message ("" when the file is accepted).
template <class Row>
std::string ErrorOf(const std::string& path, const NodeRegistry* reg = nullptr) {
  try {
    ReadAll<Row>(path, reg);
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

TEST(CsvReader, ReadsColumnsInAnyOrderWithExtrasCommentsAndCrlf) {
  TempDir dir;
  const auto path = dir.File("steps.csv",
                             "\xEF\xBB\xBFnote,agent,t1,t0,dy,dx,sxx,syy,szz,dz\r\n"
                             "# a comment\r\n"
                             "\"hello, world\",ff1,1.5,1.0,0.25,+0.5,0.01,0.02,,\r\n"
                             "\r\n"
                             "x,ff1,2.0,1.5, 1e-1 ,-0.5,,,,0.1");  // no final newline, complete
  const auto rows = ReadAll<Step>(path);
  ASSERT_EQ(rows.size(), 2u);
  EXPECT_EQ(rows[0].agent, "ff1");
  EXPECT_DOUBLE_EQ(rows[0].t0, 1.0);
  EXPECT_DOUBLE_EQ(rows[0].t1, 1.5);
  EXPECT_DOUBLE_EQ(rows[0].delta_n.x(), 0.5);
  EXPECT_DOUBLE_EQ(rows[0].delta_n.y(), 0.25);
  ASSERT_TRUE(rows[0].variance_m2.has_value());
  EXPECT_DOUBLE_EQ(rows[0].variance_m2->y(), 0.02);
  EXPECT_DOUBLE_EQ(rows[1].delta_n.y(), 0.1);
  EXPECT_DOUBLE_EQ(rows[1].delta_n.z(), 0.1);
  EXPECT_FALSE(rows[1].variance_m2.has_value());  // empty cells = unknown
}

TEST(CsvReader, MissingColumnNamesTheColumnAndFile) {
  TempDir dir;
  const auto path = dir.File("rssi.csv", "t,rx,rssi_dbm\n1,a,-50\n");
  EXPECT_THAT(ErrorOf<RssiPacket>(path),
              AllOf(HasSubstr("rssi.csv:1:"), HasSubstr("missing column 'tx'")));
}

TEST(CsvReader, NonNumericCellNamesLineAndColumn) {
  TempDir dir;
  const auto path = dir.File("rssi.csv", "t,rx,tx,rssi_dbm\n1,a,b,-50\n2,a,b,loud\n");
  EXPECT_THAT(ErrorOf<RssiPacket>(path),
              AllOf(HasSubstr("rssi.csv:3:"), HasSubstr("'rssi_dbm'"), HasSubstr("'loud'")));
}

TEST(CsvReader, RejectsNanAndInfinity) {
  TempDir dir;
  for (const char* bad : {"nan", "NaN", "inf", "-inf", "1e999"}) {
    const auto path = dir.File("truth.csv", std::string("t,id,x,y\n0,a,1,2\n1,a,") + bad + ",2\n");
    EXPECT_THAT(ErrorOf<TruthSample>(path),
                AllOf(HasSubstr("truth.csv:3:"), HasSubstr("not a finite number")))
        << bad;
  }
}

TEST(CsvReader, EmptyRequiredCellIsAnError) {
  TempDir dir;
  const auto path = dir.File("truth.csv", "t,id,x,y\n0,a,,2\n");
  EXPECT_THAT(ErrorOf<TruthSample>(path), AllOf(HasSubstr(":2:"), HasSubstr("empty cell")));
}

TEST(CsvReader, UnknownNodeIdIsRejectedWithRegistry) {
  TempDir dir;
  const auto path = dir.File("rssi.csv", "t,rx,tx,rssi_dbm\n1,ff1,c1,-50\n2,ff1,ghost,-60\n");
  NodeRegistry reg;
  reg.Add("ff1");
  reg.Add("c1");
  EXPECT_THAT(ErrorOf<RssiPacket>(path, &reg),
              AllOf(HasSubstr("rssi.csv:3:"), HasSubstr("unknown node id 'ghost'")));
  EXPECT_EQ(ErrorOf<RssiPacket>(path), "");  // without a registry only the syntax is checked
}

TEST(CsvReader, MalformedNodeIdIsRejected) {
  TempDir dir;
  const auto path = dir.File("rssi.csv", "t,rx,tx,rssi_dbm\n1,ff 1,c1,-50\n");
  EXPECT_THAT(ErrorOf<RssiPacket>(path), AllOf(HasSubstr(":2:"), HasSubstr("not a node id")));
}

TEST(CsvReader, RowsOutOfTimeOrderAreRejectedNamingBothLines) {
  TempDir dir;
  const auto path = dir.File("truth.csv", "t,id,x,y\n0,a,0,0\n2,a,0,0\n1,a,0,0\n");
  EXPECT_THAT(ErrorOf<TruthSample>(path),
              AllOf(HasSubstr("truth.csv:4:"), HasSubstr("out of time order"),
                    HasSubstr("line 3")));
}

TEST(CsvReader, StepsAreOrderedByT1AndT1MustNotPrecedeT0) {
  TempDir dir;
  EXPECT_EQ(ErrorOf<Step>(dir.File("a.csv", "t0,t1,agent,dx,dy\n0,2,a,0,0\n1,2,a,0,0\n")), "");
  EXPECT_THAT(ErrorOf<Step>(dir.File("b.csv", "t0,t1,agent,dx,dy\n3,2,a,0,0\n")),
              HasSubstr("before t0"));
}

// Values no sensor produces are a wrong unit or a corrupted row: rejected with file and line.
TEST(CsvReader, ImplausibleTimeRssiAndStepLengthAreRejected) {
  TempDir dir;
  EXPECT_THAT(ErrorOf<TruthSample>(dir.File("t.csv", "t,id,x,y\n0,a,0,0\n1e300,a,0,0\n")),
              AllOf(HasSubstr("t.csv:3:"), HasSubstr("not plausible")));
  EXPECT_EQ(ErrorOf<TruthSample>(dir.File("epoch.csv", "t,id,x,y\n1763776000.25,a,0,0\n")), "");
  EXPECT_THAT(ErrorOf<Step>(dir.File("s0.csv", "t0,t1,agent,dx,dy\n-1e11,2,a,0,0\n")),
              AllOf(HasSubstr("s0.csv:2:"), HasSubstr("not plausible")));
  EXPECT_THAT(ErrorOf<Step>(dir.File("s1.csv", "t0,t1,agent,dx,dy\n0,1,a,0.7,0\n1,2,a,1e300,0\n")),
              AllOf(HasSubstr("s1.csv:3:"), HasSubstr("not a plausible foot displacement")));
  const std::string rssi_header = "t,rx,tx,rssi_dbm\n";
  EXPECT_EQ(ErrorOf<RssiPacket>(dir.File("r0.csv", rssi_header + "0,a,b,-95.5\n1,a,b,-3\n")), "");
  for (const char* bad : {"1e300", "75", "-250"}) {
    EXPECT_THAT(ErrorOf<RssiPacket>(dir.File("r1.csv", rssi_header + "0,a,b," + bad + "\n")),
                AllOf(HasSubstr("r1.csv:2:"), HasSubstr("not a received power in dBm")))
        << bad;
  }
}

TEST(CsvReader, TruncatedLastLineIsReported) {
  TempDir dir;
  const auto path = dir.File("imu.csv", "t,agent,ax,ay,az,gx,gy,gz\n0,ff1,0,0,9.8,0,0,0\n0.01,ff1,0,");
  EXPECT_THAT(ErrorOf<ImuSample>(path), AllOf(HasSubstr("imu.csv:3:"), HasSubstr("truncated")));
}

TEST(CsvReader, WrongFieldCountInTheMiddle) {
  TempDir dir;
  const auto path = dir.File("truth.csv", "t,id,x,y\n0,a,0,0,5\n");
  EXPECT_THAT(ErrorOf<TruthSample>(path), AllOf(HasSubstr(":2:"), HasSubstr("expected 4 fields")));
}

TEST(CsvReader, EmptyFileAndMissingFile) {
  TempDir dir;
  EXPECT_THAT(ErrorOf<TruthSample>(dir.File("truth.csv", "")), HasSubstr("empty file"));
  EXPECT_THAT(ErrorOf<TruthSample>(dir.File("c.csv", "# only a comment\n\n")),
              HasSubstr("empty file"));
  EXPECT_THAT(ErrorOf<TruthSample>((dir.path() / "nope.csv").string()),
              HasSubstr("does not exist"));
  EXPECT_EQ(ReadAll<TruthSample>(dir.File("h.csv", "t,id,x,y\n")).size(), 0u);  // header only
}

TEST(CsvReader, DuplicateHeaderColumn) {
  TempDir dir;
  EXPECT_THAT(ErrorOf<TruthSample>(dir.File("truth.csv", "t,id,x,x,y\n")),
              HasSubstr("'x' appears twice"));
}

TEST(CsvReader, HugeBinaryFileFailsFastWithoutReadingItAll) {
  // A 2 GB file of NUL bytes (sparse: costs no disk) after a valid header.
  TempDir dir;
  const auto path = dir.File("imu.csv", "t,agent,ax,ay,az,gx,gy,gz\n");
  std::filesystem::resize_file(path, 2ull << 30);
  const std::string error = ErrorOf<ImuSample>(path);
  EXPECT_THAT(error, AllOf(HasSubstr("imu.csv:2:"), HasSubstr("not a CSV text file")));
}

TEST(CsvReader, HugeSingleLineIsRejected) {
  TempDir dir;
  const auto path = dir.File("truth.csv", "t,id,x,y\n0,a,0," + std::string(3u << 20, '1') + "\n");
  EXPECT_THAT(ErrorOf<TruthSample>(path), HasSubstr("line longer than"));
}

TEST(CsvReader, StreamsAcrossChunkBoundaries) {
  // A tiny chunk size forces every refill path; rows must come out identical.
  TempDir dir;
  const auto truth = SyntheticTruth(2000, 7);
  const auto path = (dir.path() / "truth.csv").string();
  WriteAll(path, truth);
  RowReader<TruthSample> reader(path, nullptr, {.max_line_bytes = 256, .chunk_bytes = 64});
  TruthSample row;
  std::size_t i = 0;
  while (reader.Next(row)) {
    ASSERT_LT(i, truth.size());
    EXPECT_EQ(row.position_n, truth[i].position_n);
    ++i;
  }
  EXPECT_EQ(i, truth.size());
}

template <class Row>
void ExpectRoundTrip(const std::vector<Row>& rows, auto&& equal) {
  TempDir dir;
  const auto path = (dir.path() / StreamFileName<Row>()).string();
  WriteAll(path, rows);
  const auto back = ReadAll<Row>(path);
  ASSERT_EQ(back.size(), rows.size());
  for (std::size_t i = 0; i < rows.size(); ++i) ASSERT_TRUE(equal(rows[i], back[i])) << i;
}

TEST(Streams, EveryKindRoundTripsExactly) {
  ExpectRoundTrip(SyntheticImu(500, 1), [](const ImuSample& a, const ImuSample& b) {
    return a.t == b.t && a.agent == b.agent && a.accel_b == b.accel_b && a.gyro_b == b.gyro_b;
  });
  ExpectRoundTrip(SyntheticSteps(500, 2), [](const Step& a, const Step& b) {
    return a.t0 == b.t0 && a.t1 == b.t1 && a.delta_n == b.delta_n && *a.variance_m2 == *b.variance_m2;
  });
  ExpectRoundTrip(SyntheticRssi(500, 3), [](const RssiPacket& a, const RssiPacket& b) {
    return a.t == b.t && a.rx == b.rx && a.tx == b.tx && a.rssi_dbm == b.rssi_dbm;
  });
  ExpectRoundTrip(SyntheticEstimates(500, 4), [](const Estimate& a, const Estimate& b) {
    return a.t == b.t && a.id == b.id && a.position_n == b.position_n && a.sxx == b.sxx &&
           a.sxy == b.sxy && a.syy == b.syy;
  });
  ExpectRoundTrip(std::vector<RangeMeasurement>{{0.5, "a", "b", 3.25, 0.1, "uwb"},
                                                {0.7, "a", "c", 1.0, std::nullopt, ""}},
                  [](const RangeMeasurement& a, const RangeMeasurement& b) {
                    return a.t == b.t && a.range_m == b.range_m && a.sigma_m == b.sigma_m &&
                           a.kind == b.kind;
                  });
  ExpectRoundTrip(std::vector<BearingMeasurement>{{0.5, "a", "b", -1.25, 0.3}},
                  [](const BearingMeasurement& a, const BearingMeasurement& b) {
                    return a.bearing_rad == b.bearing_rad && a.sigma_rad == b.sigma_rad;
                  });
  ExpectRoundTrip(std::vector<MissionEvent>{{0, "ff1", "enter", ""}, {1, "ff1", "drop", "c1"}},
                  [](const MissionEvent& a, const MissionEvent& b) {
                    return a.t == b.t && a.event == b.event && a.node == b.node;
                  });
  ExpectRoundTrip(std::vector<BaroSample>{{0.25, "ff1", 1013.25}, {0.5, "ff1", 1012.987654321}},
                  [](const BaroSample& a, const BaroSample& b) {
                    return a.t == b.t && a.agent == b.agent && a.pressure_hpa == b.pressure_hpa;
                  });
}

TEST(CsvReader, ImuValuesBeyondAnySensorAreRefused) {
  TempDir dir;
  const std::string header = "t,agent,ax,ay,az,gx,gy,gz\n";
  EXPECT_EQ(ErrorOf<ImuSample>(dir.File("imu.csv", header + "0,ff1,0,0,9.8,0.1,0,0\n")), "");
  EXPECT_THAT(ErrorOf<ImuSample>(dir.File("i1.csv", header + "0,ff1,1e300,0,9.8,0,0,0\n")),
              AllOf(HasSubstr("i1.csv:2:"), HasSubstr("beyond any foot IMU")));
  EXPECT_THAT(ErrorOf<ImuSample>(dir.File("i2.csv", header + "0,ff1,0,0,9.8,0,0,360\n")),
              AllOf(HasSubstr("i2.csv:2:"), HasSubstr("deg/s?")));
}

TEST(CsvReader, BarometerRowsAreCheckedLikeEveryStream) {
  TempDir dir;
  const std::string header = "t,agent,pressure_hpa\n";
  EXPECT_EQ(ErrorOf<BaroSample>(dir.File("baro.csv", header + "0,ff1,1013.2\n1,ff1,1013.1\n")), "");
  for (const char* bad : {"101325", "101.3", "-5"}) {  // Pa, kPa, nonsense
    EXPECT_THAT(ErrorOf<BaroSample>(dir.File("b1.csv", header + "0,ff1," + std::string(bad) + "\n")),
                AllOf(HasSubstr("b1.csv:2:"), HasSubstr("not an air pressure in hPa")))
        << bad;
  }
  EXPECT_THAT(ErrorOf<BaroSample>(dir.File("b2.csv", header + "1,ff1,1013\n0,ff1,1013\n")),
              HasSubstr("out of time order"));
  EXPECT_THAT(ErrorOf<BaroSample>(dir.File("b3.csv", "t,agent\n0,ff1\n")),
              HasSubstr("pressure_hpa"));
}

TEST(CsvReader, ImplausibleVariancesRangesAndAnglesAreRefusedWithTheirLine) {
  // Issue 30, item 3: a step variance of 1e300 gave positions of 1e125 m.
  TempDir dir;
  const std::string steps = "t0,t1,agent,dx,dy,dz,sxx,syy,szz\n";
  EXPECT_EQ(ErrorOf<Step>(dir.File("s0.csv", steps + "0,1,ff1,0.7,0,0,0.01,0.01,0.001\n")), "");
  EXPECT_THAT(ErrorOf<Step>(dir.File("s1.csv", steps + "0,1,ff1,0.7,0,0,1e300,0.01,0\n")),
              AllOf(HasSubstr("s1.csv:2:"), HasSubstr("'sxx'"), HasSubstr("not plausible")));
  const std::string ranges = "t,a,b,range,sigma,kind\n";
  EXPECT_EQ(ErrorOf<RangeMeasurement>(dir.File("r0.csv", ranges + "0,b1,b2,3.2,0.1,uwb\n")), "");
  EXPECT_THAT(ErrorOf<RangeMeasurement>(dir.File("r1.csv", ranges + "0,b1,b2,1e6,0.1,uwb\n")),
              AllOf(HasSubstr("r1.csv:2:"), HasSubstr("'range'")));
  EXPECT_THAT(ErrorOf<RangeMeasurement>(dir.File("r2.csv", ranges + "0,b1,b2,3,1e308,uwb\n")),
              AllOf(HasSubstr("r2.csv:2:"), HasSubstr("'sigma'")));
  // The spec's kinds (or none); 'nan' was taken as a fourth kind with its own range bias.
  EXPECT_EQ(ErrorOf<RangeMeasurement>(dir.File(
                "r3.csv", ranges + "0,b1,b2,3,,ultrasound\n1,b1,b2,3,,rssi\n2,b1,b2,3,, uwb \n"
                                   "3,b1,b2,3,,\n")),
            "");
  EXPECT_THAT(ErrorOf<RangeMeasurement>(dir.File("r4.csv", ranges + "0,b1,b2,3,0.1,nan\n")),
              AllOf(HasSubstr("r4.csv:2:"), HasSubstr("'nan' is not a range kind"),
                    HasSubstr("ultrasound, uwb, rssi")));
  EXPECT_THAT(ErrorOf<RangeMeasurement>(dir.File("r5.csv", ranges + "0,b1,b2,3,0.1,UWB\n")),
              AllOf(HasSubstr("r5.csv:2:"), HasSubstr("'uwb'?")));
  const std::string bearings = "t,a,b,bearing,sigma\n";
  EXPECT_EQ(ErrorOf<BearingMeasurement>(dir.File("b0.csv", bearings + "0,b1,ff1,-2.5,0.3\n")), "");
  EXPECT_THAT(ErrorOf<BearingMeasurement>(dir.File("b1.csv", bearings + "0,b1,ff1,1e9,0.3\n")),
              AllOf(HasSubstr("b1.csv:2:"), HasSubstr("'bearing'")));
}

TEST(CsvReader, ADevicesStrayTimeIsRefusedNotIntegrated) {
  // Issue 30, item 3: one IMU row at t = -1e9 put every INS estimate 1e18 m away.
  TempDir dir;
  const std::string header = "t,agent,ax,ay,az,gx,gy,gz\n";
  const std::string row = ",ff1,0,0,9.8,0,0,0\n";
  EXPECT_EQ(ErrorOf<ImuSample>(dir.File("i0.csv", header + "0" + row + "0.01" + row)), "");
  EXPECT_THAT(ErrorOf<ImuSample>(dir.File("i1.csv", header + "-1e9" + row + "0" + row + "0.01" + row)),
              AllOf(HasSubstr("i1.csv:3:"), HasSubstr("line 2"), HasSubstr("stray time")));
  // Another device's first row may come much later (it was switched on): only a device's own
  // rows are compared.
  EXPECT_EQ(ErrorOf<ImuSample>(dir.File("i2.csv", header + "0" + row + "5000,ff2,0,0,9.8,0,0,0\n")),
            "");
}

TEST(CsvReader, EventNamesAreTheSpecsTrimmedAndOthersAreRefused) {
  // Issue 30, item 4: 'Stop' and 'explode' were accepted and changed results; ' stop' was
  // silently ignored.
  TempDir dir;
  const std::string header = "t,agent,event,node\n";
  EXPECT_EQ(ErrorOf<MissionEvent>(dir.File("e0.csv", header + "0,ff1, stop ,\n1,ff1,go,\n2,ff1,drop, c1\n")),
            "");
  RowReader<MissionEvent> reader((dir.path() / "e0.csv").string());
  MissionEvent e;
  ASSERT_TRUE(reader.Next(e));
  EXPECT_EQ(e.event, "stop");
  EXPECT_THAT(ErrorOf<MissionEvent>(dir.File("e1.csv", header + "0,ff1,Stop,\n")),
              AllOf(HasSubstr("e1.csv:2:"), HasSubstr("'stop'?")));
  EXPECT_THAT(ErrorOf<MissionEvent>(dir.File("e2.csv", header + "0,ff1,explode,\n")),
              AllOf(HasSubstr("e2.csv:2:"), HasSubstr("drop, wake, enter, exit, stop, go")));
}

TEST(CsvWriter, RefusesNonFiniteNumbers) {
  TempDir dir;
  RowWriter<Estimate> w((dir.path() / "estimates.csv").string());
  Estimate e{0, "ff1", Vec3(std::nan(""), 0, 0), 1, 0, 1};
  EXPECT_THROW(w.Write(e), std::logic_error);
}

TEST(CsvReader, DropEventNeedsNode) {
  TempDir dir;
  EXPECT_THAT(ErrorOf<MissionEvent>(dir.File("events.csv", "t,agent,event,node\n0,ff1,drop,\n")),
              HasSubstr("needs the dropped node"));
}

}  // namespace
}  // namespace trailmark

namespace trailmark {
namespace {

TEST(CsvMemory, ParsesADocumentInMemoryLikeAFile) {
  const std::vector<Step> steps = SyntheticSteps(300, 7);
  TempDir dir;
  const std::string path = (dir.path() / "steps.csv").string();
  WriteAll(path, steps);
  std::ifstream in(path);
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::vector<Step> from_memory = ParseAll<Step>("request body", text);
  ASSERT_EQ(from_memory.size(), steps.size());
  // FormatAll gives the very lines WriteAll wrote (header first).
  const std::vector<std::string> lines = FormatAll(from_memory);
  std::string joined;
  for (const auto& l : lines) joined += l + "\n";
  EXPECT_EQ(joined, text);
}

TEST(CsvMemory, ErrorsNameTheDocumentAndLine) {
  auto error_of = [](std::string_view text) {
    try {
      ParseAll<Step>("request body", text);
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_THAT(error_of("t0,t1,agent,dx,dy\n0,1,ff1,0.5,0\n1,2,ff1,abc,0\n"),
              AllOf(HasSubstr("request body:3:"), HasSubstr("'dx'")));
  EXPECT_THAT(error_of(""), AllOf(HasSubstr("request body"), HasSubstr("empty")));
  EXPECT_THAT(error_of("t0,t1,agent,dx\n"), HasSubstr("missing column 'dy'"));
  EXPECT_THAT(error_of(std::string("t0,t1,agent,dx,dy\n0,1,ff\0,1,0\n", 30)), HasSubstr("NUL"));
  EXPECT_EQ(error_of("t0,t1,agent,dx,dy\n"), "");  // a header alone: no rows, no error
}

}  // namespace
}  // namespace trailmark
