#include "trailmark/pipelines/pipeline_options.h"

#include <gtest/gtest.h>

#include <map>
#include <stdexcept>
#include <string>

namespace trailmark {
namespace {

std::string ErrorOf(const std::map<std::string, std::string>& values) {
  try {
    PipelineOptions o(values, "test");
    o.Whole("count", 3, 1, 100);
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "";
}

TEST(PipelineOptions, WholeReadsWholeNumbersAndTheFallback) {
  const std::map<std::string, std::string> none, given{{"count", "12"}}, exp{{"count", "1e2"}};
  EXPECT_EQ(PipelineOptions(none, "test").Whole("count", 3, 1, 100), 3);
  EXPECT_EQ(PipelineOptions(given, "test").Whole("count", 3, 1, 100), 12);
  EXPECT_EQ(PipelineOptions(exp, "test").Whole("count", 3, 1, 100), 100);
}

TEST(PipelineOptions, WholeRefusesFractionsAndValuesOutOfRangeNamingTheOption) {
  for (const std::string bad : {"2.5", "0", "-4", "101", "1e30", "nan", "ten"}) {
    const std::string e = ErrorOf({{"count", bad}});
    EXPECT_NE(e.find("option count"), std::string::npos) << bad << ": " << e;
    EXPECT_NE(e.find(bad), std::string::npos) << bad << ": " << e;
  }
  EXPECT_NE(ErrorOf({{"count", "0"}}).find("within 1 .. 100"), std::string::npos);
}

}  // namespace
}  // namespace trailmark
