// The work-unit rule (work_units.h): how many units a job is split into, and their sample ranges.
#include "server/store/work_units.h"

#include <gtest/gtest.h>

namespace tessera::server {
namespace {

// The units of a job whose record holds the settings `text`.
int units(const std::string& text, uint64_t unit_pixel_samples) {
  return unit_count(render_settings_from_text(text), unit_pixel_samples);
}

TEST(WorkUnits, AJobIsSplitByItsPixelSamples) {
  const std::string settings = R"({"width":100,"height":100,"spp":64,"time_limit_s":0,"noise_target":0})";
  EXPECT_EQ(units(settings, 0), 1);       // never split
  EXPECT_EQ(units(settings, 640000), 1);  // exactly one unit's worth
  EXPECT_EQ(units(settings, 639999), 2);  // a little more
  EXPECT_EQ(units(settings, 80000), 8);   // 8 samples each
  EXPECT_EQ(units(settings, 1), 64);      // at most one unit per sample
  EXPECT_EQ(units(settings, kDefaultUnitPixelSamples), 1);
  // 1920 x 1080 at 1024 spp: about 2.1e9 pixel samples, 107 units of 9 or 10 samples; 512 x 512 at 64 spp, one.
  EXPECT_EQ(units(R"({"width":1920,"height":1080,"spp":1024})", kDefaultUnitPixelSamples), 107);
  EXPECT_EQ(units(R"({"width":512,"height":512,"spp":64})", kDefaultUnitPixelSamples), 1);
}

TEST(WorkUnits, AJobThatStopsOnTimeOrNoiseIsOneUnit) {
  EXPECT_EQ(units(R"({"width":100,"height":100,"spp":64,"time_limit_s":10})", 1000), 1);
  EXPECT_EQ(units(R"({"width":100,"height":100,"spp":64,"noise_target":0.01})", 1000), 1);
}

// An adaptive job renders whole, so that its image (where each pixel stopped) is the same bits on one node and on a
// cluster; a frame range renders frame by frame, never split into sample ranges.
TEST(WorkUnits, AnAdaptiveJobAndAFrameRangeAreOneUnit) {
  EXPECT_EQ(units(R"({"width":100,"height":100,"spp":64,"adaptive_threshold":0.05})", 1000), 1);
  EXPECT_EQ(units(R"({"width":100,"height":100,"spp":64,"frames":{"start":1,"end":48,"step":1,"chunk":1}})", 1000), 1);
  // A range of one frame is the still at its time, split as a still is.
  EXPECT_EQ(units(R"({"width":100,"height":100,"spp":64,"frames":{"start":12,"end":12,"step":1,"chunk":1}})", 1000),
            64);
}

TEST(WorkUnits, SampleRangesAreContiguousAndCoverTheBudget) {
  const auto ranges = split_samples(10, 4);
  ASSERT_EQ(ranges.size(), 4u);
  uint32_t next = 0;
  for (const SampleRange& r : ranges) {
    EXPECT_EQ(r.first, next);
    next += r.count;
  }
  EXPECT_EQ(next, 10u);
  EXPECT_EQ(ranges[0].count, 3u);
  EXPECT_EQ(ranges[3].count, 2u);
}

}  // namespace
}  // namespace tessera::server
