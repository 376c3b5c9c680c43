// Chi-square goodness-of-fit of every non-delta model's `sample` against its `pdf`, and agreement of sample's
// value and pdf with eval/pdf (Mitsuba 3's chi2 test and pbrt-v4's bsdfs_test are the models).
#include <cstdio>

#include <gtest/gtest.h>

#include "bsdf_harness.h"

namespace tessera::test {
namespace {

constexpr int kSamples = 1000000;
constexpr double kSignificance = 0.01;

class BsdfCaseTest : public ::testing::TestWithParam<BsdfCase> {};

TEST_P(BsdfCaseTest, SampleMatchesPdfChiSquare) {
  const BsdfCase& c = GetParam();
  BsdfInstance inst(c);
  // Sidak correction: the probability that any of the chi2_test_count() tests rejects a correct model is 0.01.
  const double alpha = 1 - std::pow(1 - kSignificance, 1.0 / chi2_test_count());
  int k = 0;
  for (const Vec3& wo : incident_directions(c)) {
    Chi2Result r = chi2_test(inst.bsdf(), wo, kSamples, 0x7e55e7a + 977 * k++);
    std::printf("[chi2] %-28s wo=(%.3f %.3f %.3f) chi2=%.1f dof=%d p=%.4g  int(pdf)=%.4f sampled=%.4f\n",
                c.name.c_str(), wo.x, wo.y, wo.z, r.statistic, r.dof, r.p_value, r.pdf_integral, r.sampled_fraction);
    EXPECT_TRUE(r.failure.empty()) << c.name << " wo=(" << wo.x << "," << wo.y << "," << wo.z << "): " << r.failure;
    EXPECT_GE(r.p_value, alpha) << c.name << " wo=(" << wo.x << "," << wo.y << "," << wo.z
                                << "): sample() does not follow pdf(); chi2=" << r.statistic << " dof=" << r.dof;
    // pdf integrates to at most 1, and to the fraction of samples the sampler returns as non-delta directions
    // (1 where it discards nothing and has no delta lobe).
    EXPECT_LE(r.pdf_integral, 1.002) << c.name;
    EXPECT_NEAR(r.pdf_integral, r.sampled_fraction, 0.005) << c.name;
  }
}

TEST_P(BsdfCaseTest, SampleAgreesWithEvalAndPdf) {
  const BsdfCase& c = GetParam();
  BsdfInstance inst(c);
  const Bsdf& bsdf = inst.bsdf();
  std::mt19937_64 rng(12345);
  int checked = 0;
  for (const Vec3& wo : incident_directions(c)) {
    for (int i = 0; i < 4000; ++i) {
      std::optional<BsdfSample> s = bsdf.sample(wo, uniform01(rng), Vec2(uniform01(rng), uniform01(rng)));
      if (!s) continue;
      EXPECT_NEAR(length(s->wi), 1.0f, 1e-4f);
      EXPECT_TRUE(s->pdf > 0 && std::isfinite(s->pdf));
      if (is_delta(s->flags)) {
        // Delta lobes are invisible to eval/pdf; their weight must still be finite and non-negative.
        EXPECT_TRUE(is_finite(s->f) && s->f.x >= 0 && s->f.y >= 0 && s->f.z >= 0);
        continue;
      }
      const Rgb f = bsdf.eval(wo, s->wi);
      const float pdf = bsdf.pdf(wo, s->wi);
      ASSERT_NEAR(s->pdf, pdf, 2e-3f * std::max(pdf, 1.0f)) << c.name;
      for (int ch = 0; ch < 3; ++ch) ASSERT_NEAR(s->f[ch], f[ch], 2e-3f * std::max(f[ch], 1.0f)) << c.name;
      // Reflection samples stay on wo's side, transmission samples cross.
      const bool transmitted = s->wi.z * wo.z < 0;
      EXPECT_EQ(transmitted, (s->flags & kBsdfTransmission) != 0) << c.name;
      ++checked;
    }
  }
  EXPECT_GT(checked, 1000) << c.name;
}

// A BSDF that says it has one lobe (kBsdfOneLobe) is sampled with no lobe choice by the integrator: its samples
// must not depend on `uc`. A mix of two parts chooses between them with it, so it must never say so.
TEST(BsdfOneLobe, SamplesIgnoreTheLobeChoice) {
  int one_lobe = 0;
  for (const BsdfCase& c : bsdf_cases()) {
    BsdfInstance inst(c);
    const Bsdf& bsdf = inst.bsdf();
    if (c.material.value("type", "") == "mix") {
      EXPECT_FALSE(bsdf.flags() & kBsdfOneLobe) << c.name;
    }
    if (!(bsdf.flags() & kBsdfOneLobe)) continue;
    ++one_lobe;
    std::mt19937_64 rng(777);
    for (const Vec3& wo : incident_directions(c)) {
      for (int i = 0; i < 2000; ++i) {
        const Vec2 u(uniform01(rng), uniform01(rng));
        const std::optional<BsdfSample> a = bsdf.sample(wo, 0.0f, u), b = bsdf.sample(wo, uniform01(rng), u);
        ASSERT_EQ(a.has_value(), b.has_value()) << c.name;
        if (!a) continue;
        EXPECT_EQ(a->wi.x, b->wi.x) << c.name;
        EXPECT_EQ(a->wi.y, b->wi.y) << c.name;
        EXPECT_EQ(a->wi.z, b->wi.z) << c.name;
        EXPECT_EQ(a->pdf, b->pdf) << c.name;
        EXPECT_EQ(a->flags, b->flags) << c.name;
      }
    }
  }
  EXPECT_GE(one_lobe, 1);  // Lambert
}

INSTANTIATE_TEST_SUITE_P(AllModels, BsdfCaseTest, ::testing::ValuesIn(bsdf_cases()),
                         [](const ::testing::TestParamInfo<BsdfCase>& info) { return info.param.name; });

}  // namespace
}  // namespace tessera::test
