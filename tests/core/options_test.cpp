// SPDX-License-Identifier: MIT
// OptionTable: typed options from text, described once (core/options.h).
#include "trailmark/core/options.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace trailmark {
namespace {

using ::testing::HasSubstr;

enum class Mode { kFast, kExact };

struct Inner {
  double gain = 2.5;  ///< the default, read by Describe
};

struct Options {
  double sigma_m = 0.3;
  int count = 3;
  std::optional<double> gamma;
  bool enabled = true;
  Mode mode = Mode::kExact;
  double seconds = 0.05;
  Inner inner;
};

OptionTable<Inner> InnerTable() {
  OptionTable<Inner> t;
  t.Real("gain", &Inner::gain, "", OptionBounds::Positive(), "a gain");
  return t;
}

OptionTable<Options> Table() {
  OptionTable<Options> t;
  t.Real("sigma_m", &Options::sigma_m, "m", OptionBounds::Positive(), "a sigma");
  t.Integer("count", &Options::count, OptionBounds::Between(1, 100), "a count")
      .AlsoSets([](Options& o) { o.seconds = 0; });
  t.Real("gamma", &Options::gamma, "", OptionBounds::Positive(), "a threshold", "auto");
  t.Flag("enabled", &Options::enabled, "a flag");
  t.Choice("mode", &Options::mode,
           std::vector<std::pair<std::string, Mode>>{{"fast", Mode::kFast}, {"exact", Mode::kExact}},
           "a mode");
  t.Include("inner.", &Options::inner, InnerTable());
  return t;
}

std::string ErrorOf(const OptionValues& values) {
  Options o;
  std::string why;
  return Table().Apply(values, &o, &why) ? "" : why;
}

TEST(OptionTable, DescribesEveryKeyWithTheStructsDefaults) {
  const auto info = Table().Describe();
  ASSERT_EQ(info.size(), 6u);
  EXPECT_EQ(info[0].key, "sigma_m");
  EXPECT_EQ(info[0].default_value, "0.3");
  EXPECT_EQ(info[0].unit, "m");
  EXPECT_EQ(info[0].bounds.Describe(), "> 0");
  EXPECT_EQ(info[1].type, OptionType::kInteger);
  EXPECT_EQ(info[1].default_value, "3");
  EXPECT_EQ(info[1].bounds.Describe(), "within 1 .. 100");
  EXPECT_EQ(info[2].default_value, "auto");
  EXPECT_EQ(info[3].default_value, "true");
  EXPECT_EQ(info[4].default_value, "exact");
  EXPECT_THAT(info[4].choices, ::testing::ElementsAre("fast", "exact"));
  EXPECT_EQ(info[5].key, "inner.gain");
  EXPECT_EQ(info[5].default_value, "2.5");
  // Other defaults: the instance given.
  Options mine;
  mine.count = 7;
  EXPECT_EQ(Table().Describe(mine)[1].default_value, "7");
}

TEST(OptionTable, AppliesValuesOfEveryType) {
  Options o;
  std::string why;
  ASSERT_TRUE(Table().Apply({{"sigma_m", "0.5"},
                             {"count", "1e1"},
                             {"gamma", "+3e7"},
                             {"enabled", "off"},
                             {"mode", "fast"},
                             {"inner.gain", "4"}},
                            &o, &why))
      << why;
  EXPECT_EQ(o.sigma_m, 0.5);
  EXPECT_EQ(o.count, 10);
  EXPECT_EQ(o.seconds, 0.0);  // what setting count also sets
  EXPECT_EQ(o.gamma, 3e7);
  EXPECT_FALSE(o.enabled);
  EXPECT_EQ(o.mode, Mode::kFast);
  EXPECT_EQ(o.inner.gain, 4.0);
  Options untouched;
  ASSERT_TRUE(Table().Apply({}, &untouched, &why));
  EXPECT_EQ(untouched.seconds, 0.05);
}

TEST(OptionTable, RefusesBadValuesNamingTheKeyAndTheValue) {
  for (const std::string bad : {"2.5", "0", "-4", "101", "1e30", "nan", "ten", "", "3 "}) {
    const std::string e = ErrorOf({{"count", bad}});
    EXPECT_THAT(e, HasSubstr("option count='" + bad + "'")) << bad;
    EXPECT_THAT(e, HasSubstr("whole number")) << bad;
  }
  EXPECT_THAT(ErrorOf({{"count", "0"}}), HasSubstr("within 1 .. 100"));
  EXPECT_THAT(ErrorOf({{"sigma_m", "0"}}), HasSubstr("must be > 0"));
  EXPECT_THAT(ErrorOf({{"sigma_m", "inf"}}), HasSubstr("not a finite number"));
  EXPECT_THAT(ErrorOf({{"sigma_m", "0.1m"}}), HasSubstr("not a finite number"));
  EXPECT_THAT(ErrorOf({{"enabled", "maybe"}}), HasSubstr("not a boolean"));
  EXPECT_THAT(ErrorOf({{"mode", "slow"}}), HasSubstr("must be one of fast, exact"));
  EXPECT_THAT(ErrorOf({{"inner.gain", "-1"}}), HasSubstr("option inner.gain='-1' must be > 0"));
}

TEST(OptionTable, AnUnknownKeyNamesTheValidOnes) {
  const std::string e = ErrorOf({{"sigma", "1"}});
  EXPECT_THAT(e, HasSubstr("unknown option 'sigma'"));
  EXPECT_THAT(e, HasSubstr("known: sigma_m, count, gamma, enabled, mode, inner.gain"));
  OptionTable<Options> empty;
  Options o;
  std::string why;
  EXPECT_FALSE(empty.Apply({{"x", "1"}}, &o, &why));
  EXPECT_THAT(why, HasSubstr("it takes none"));
}

TEST(OptionBounds, OpenAndClosedEnds) {
  EXPECT_TRUE(OptionBounds::NonNegative().Contains(0));
  EXPECT_FALSE(OptionBounds::Positive().Contains(0));
  EXPECT_TRUE(OptionBounds::Inside(0, 1).Contains(0.5));
  EXPECT_FALSE(OptionBounds::Inside(0, 1).Contains(1));
  EXPECT_EQ(OptionBounds::Inside(0, 1).Describe(), "> 0 and < 1");
  EXPECT_EQ(OptionBounds::Any().Describe(), "");
  EXPECT_FALSE(OptionBounds::Any().Contains(std::nan("")));
}

}  // namespace
}  // namespace trailmark
