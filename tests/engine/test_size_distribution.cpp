// Gradings: the sampled grains against each grading's closed forms.
#include "engine/packing.hpp"
#include "engine/size_distribution.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace demcal::engine {
namespace {

constexpr double kA = 1e-3, kB = 2e-3;

// Mass fraction finer than d, as a laboratory's sieve curve gives it.
double closed_form_finer(SizeDistribution s, double d) {
  switch (s) {
    case SizeDistribution::uniform: return (std::pow(d, 4) - std::pow(kA, 4)) / (std::pow(kB, 4) - std::pow(kA, 4));
    case SizeDistribution::uniform_mass: return (d - kA) / (kB - kA);
    case SizeDistribution::log_uniform_mass: return std::log(d / kA) / std::log(kB / kA);
  }
  return NAN;
}

TEST(SizeDistribution, MassFinerThanIsEachGradingsOwnCurve) {
  for (SizeDistribution s : kSizeDistributions) {
    const Grading g{s, kA, kB};
    for (double d : {1.1e-3, 1.25e-3, 1.5e-3, 1.9e-3})
      EXPECT_NEAR(g.finer_by_mass(d), closed_form_finer(s, d), 1e-12) << to_string(s) << " d " << d;
    EXPECT_EQ(g.finer_by_mass(0.5e-3), 0.0);
    EXPECT_EQ(g.finer_by_mass(3e-3), 1.0);
  }
}

TEST(SizeDistribution, DrawnGrainsFollowTheGradingByMassAndByNumber) {
  const int n = 400000;
  for (SizeDistribution s : kSizeDistributions) {
    const Grading g{s, kA, kB};
    std::mt19937_64 rng(7);
    double sum = 0, sum3 = 0, mass_below = 0;
    const double mid = 1.4e-3;
    for (int i = 0; i < n; ++i) {
      const double d = g.draw(rng);
      ASSERT_GE(d, kA);
      ASSERT_LE(d, kB);
      sum += d;
      sum3 += d * d * d;
      if (d < mid) mass_below += d * d * d;
    }
    // Sampling errors at n = 4e5 are ~1e-3 relative; the gradings differ by far more
    // (mean diameter 1.5, 1.333 and 1.286 mm).
    EXPECT_NEAR(sum / n / g.mean(), 1.0, 2e-3) << to_string(s);
    EXPECT_NEAR(sum3 / n / g.mean_cube(), 1.0, 4e-3) << to_string(s);
    EXPECT_NEAR(mass_below / sum3, closed_form_finer(s, mid), 4e-3) << to_string(s);
  }
  EXPECT_NEAR(Grading({SizeDistribution::uniform, kA, kB}).mean(), 1.5e-3, 1e-15);
  EXPECT_NEAR(Grading({SizeDistribution::uniform_mass, kA, kB}).mean(), 4.0 / 3.0 * 1e-3, 1e-15);
  EXPECT_NEAR(Grading({SizeDistribution::log_uniform_mass, kA, kB}).mean(), 9.0 / 7.0 * 1e-3, 1e-15);
}

TEST(SizeDistribution, TheDefaultDrawsTheSameGrainsAsBefore) {
  // Samples and stored results of jobs without a grading must not move.
  std::mt19937_64 a(3), b(3);
  const std::vector<double> r = sample_radii(1000, Grading{SizeDistribution::uniform, kA, kB}, a);
  for (double x : r) EXPECT_EQ(x, 0.5 * uniform(b, kA, kB));
  const std::vector<double> old = sample_radii(5, kA, kB, b);
  std::mt19937_64 c(3);
  sample_radii(1000, Grading{SizeDistribution::uniform, kA, kB}, c);
  EXPECT_EQ(sample_radii(5, Grading{SizeDistribution::uniform, kA, kB}, c), old);
}

TEST(SizeDistribution, NarrowRangesStayInsideTheRange) {
  // The ratios of integrals cancel when d_max is close to d_min; the closed forms do not.
  for (SizeDistribution s : kSizeDistributions)
    for (double rel : {1e-6, 1e-10, 1e-13}) {
      const Grading g{s, kA, kA * (1 + rel)};
      EXPECT_GE(g.mean(), g.d_min) << to_string(s) << " " << rel;
      EXPECT_LE(g.mean(), g.d_max) << to_string(s) << " " << rel;
      EXPECT_NEAR(g.mean_cube() / (kA * kA * kA), 1.0, 4 * rel + 1e-15) << to_string(s) << " " << rel;
      std::mt19937_64 rng(5);
      for (int i = 0; i < 1000; ++i) {
        const double d = g.draw(rng);
        ASSERT_GE(d, g.d_min);
        ASSERT_LE(d, g.d_max);
      }
    }
}

TEST(SizeDistribution, NamesRoundTripAndOneSizeIsOneSize) {
  for (SizeDistribution s : kSizeDistributions) {
    SizeDistribution back = SizeDistribution::uniform;
    ASSERT_TRUE(parse_size_distribution(to_string(s), back));
    EXPECT_EQ(back, s);
    const Grading one{s, kA, kA};
    std::mt19937_64 rng(1);
    EXPECT_EQ(one.draw(rng), kA);
    EXPECT_EQ(one.mean(), kA);
    EXPECT_NEAR(one.mean_cube(), kA * kA * kA, 1e-24);
  }
  SizeDistribution s = SizeDistribution::uniform_mass;
  EXPECT_FALSE(parse_size_distribution("lognormal", s));
  EXPECT_EQ(s, SizeDistribution::uniform_mass);
}

}  // namespace
}  // namespace demcal::engine
