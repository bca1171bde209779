// Gradings: the sampled grains against each grading's closed forms.
#include "engine/errors.hpp"
#include "engine/material.hpp"
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

// A sand's measured curve, cut to the simulated range: sizes in m, fraction finer by mass.
const SieveCurve kSand{{0.6e-3, 1e-3, 1.18e-3, 1.4e-3, 1.7e-3, 2e-3, 2.36e-3}, {0, 0.10, 0.25, 0.55, 0.80, 0.95, 1}};
constexpr SizeDistribution kMassKinds[] = {SizeDistribution::uniform_mass, SizeDistribution::log_uniform_mass};

TEST(SieveCurve, AStraightTwoPointCurveIsTheRangesOwnGrading) {
  for (SizeDistribution s : kMassKinds) {
    const Grading line{s, kA, kB}, curve{s, kA, kB, SieveCurve{{kA, kB}, {0, 1}}};
    EXPECT_NEAR(curve.mean() / line.mean(), 1.0, 1e-14) << to_string(s);
    EXPECT_NEAR(curve.mean_cube() / line.mean_cube(), 1.0, 1e-14) << to_string(s);
    for (double d : {1.1e-3, 1.5e-3, 1.9e-3}) EXPECT_NEAR(curve.finer_by_mass(d), line.finer_by_mass(d), 1e-14);
    // The same curve with a point on its own line changes nothing.
    const double mid = 1.3e-3;
    const Grading split{s, kA, kB, SieveCurve{{kA, mid, kB}, {0, line.finer_by_mass(mid), 1}}};
    EXPECT_NEAR(split.mean() / line.mean(), 1.0, 1e-14) << to_string(s);
    EXPECT_NEAR(split.mean_cube() / line.mean_cube(), 1.0, 1e-14) << to_string(s);
  }
}

TEST(SieveCurve, TheWholeCurveDrawsItsOwnMeans) {
  const int n = 400000;
  for (SizeDistribution s : kMassKinds) {
    const Grading g{s, kSand.d.front(), kSand.d.back(), kSand};
    ASSERT_EQ(g.problem(), "");
    std::mt19937_64 rng(5);
    double sum = 0, sum2 = 0, sum3 = 0;
    for (int i = 0; i < n; ++i) {
      const double d = g.draw(rng);
      sum += d;
      sum2 += d * d;
      sum3 += d * d * d;
    }
    const double sd = std::sqrt(sum2 / n - (sum / n) * (sum / n));
    EXPECT_NEAR(sum / n / g.mean(), 1.0, 5.0 * sd / g.mean() / std::sqrt(n)) << to_string(s);
    EXPECT_NEAR(sum3 / n / g.mean_cube(), 1.0, 6e-3) << to_string(s);
  }
}

TEST(SieveCurve, DrawnGrainsPassEachSieveAsTheCurveSaysWithinTheCut) {
  // Cut to [1, 2] mm: 85% of the curve's mass, renormalised.
  const int n = 400000;
  for (SizeDistribution s : kMassKinds) {
    const Grading g{s, 1e-3, 2e-3, kSand};
    ASSERT_EQ(g.problem(), "");
    std::mt19937_64 rng(11);
    double sum = 0, sum3 = 0;
    std::vector<double> d3;
    d3.reserve(n);
    for (int i = 0; i < n; ++i) {
      const double d = g.draw(rng);
      ASSERT_GE(d, 1e-3);
      ASSERT_LE(d, 2e-3);
      sum += d;
      sum3 += d * d * d;
      d3.push_back(d);
    }
    EXPECT_NEAR(sum / n / g.mean(), 1.0, 2e-3) << to_string(s);
    EXPECT_NEAR(sum3 / n / g.mean_cube(), 1.0, 4e-3) << to_string(s);
    for (std::size_t k = 2; k + 1 < kSand.d.size(); ++k) {  // the sieves inside the cut
      double below = 0;
      for (double d : d3) below += d < kSand.d[k] ? d * d * d : 0.0;
      const double expected = (kSand.finer[k] - 0.10) / (0.95 - 0.10);
      EXPECT_NEAR(below / sum3, expected, 4e-3) << to_string(s) << " sieve " << kSand.d[k];
      EXPECT_NEAR(g.finer_by_mass(kSand.d[k]), expected, 1e-14);
    }
    // Between sieves the curve is a straight line on its chart: in d, or in log d.
    const double x = 1.5e-3, t = s == SizeDistribution::uniform_mass ? (x - 1.4e-3) / (1.7e-3 - 1.4e-3)
                                                                      : std::log(x / 1.4e-3) / std::log(1.7e-3 / 1.4e-3);
    EXPECT_NEAR(g.finer_by_mass(x), (0.55 + t * 0.25 - 0.10) / 0.85, 1e-14) << to_string(s);
  }
}

TEST(SieveCurve, AGapInTheCurveGetsNoGrains) {
  // Gap-graded: nothing between 1.2 and 1.8 mm.
  const Grading g{SizeDistribution::log_uniform_mass, kA, kB, SieveCurve{{kA, 1.2e-3, 1.8e-3, kB}, {0, 0.5, 0.5, 1}}};
  ASSERT_EQ(g.problem(), "");
  const auto pieces = g.pieces();
  ASSERT_EQ(pieces.size(), 3u);
  EXPECT_EQ(pieces[1].number, 0.0);
  EXPECT_NEAR(pieces[0].mass + pieces[2].mass, 1.0, 1e-15);
  EXPECT_NEAR(pieces[0].number + pieces[2].number, 1.0, 1e-15);
  EXPECT_GT(pieces[0].number, 3.0 * pieces[2].number);  // equal masses: far more small grains
  std::mt19937_64 rng(2);
  for (int i = 0; i < 100000; ++i) {
    const double d = g.draw(rng);
    ASSERT_TRUE(d <= 1.2e-3 || d >= 1.8e-3) << d;
  }
}

TEST(SieveCurve, CurvesThatCannotBeAGradingSayWhy) {
  const auto problem = [](SieveCurve c, double lo = kA, double hi = kB,
                          SizeDistribution s = SizeDistribution::log_uniform_mass) {
    return Grading{s, lo, hi, std::move(c)}.problem();
  };
  EXPECT_EQ(problem({{kA, kB}, {0, 1}}), "");
  EXPECT_NE(problem({{kA}, {0}}).find("at least two sizes"), std::string::npos);
  EXPECT_NE(problem({{kA, kA, kB}, {0, 0.5, 1}}).find("point 2 (d = 0.001 m): sizes must increase"), std::string::npos);
  EXPECT_NE(problem({{kA, 1.5e-3, kB}, {0, 0.6, 0.5}}).find("point 3 (d = 0.002 m): the mass finer must not decrease"),
            std::string::npos);
  EXPECT_NE(problem({{kA, kB}, {0.1, 1}}).find("first size"), std::string::npos);
  EXPECT_NE(problem({{kA, kB}, {0, 0.9}}).find("last size"), std::string::npos);
  EXPECT_NE(problem({{kA, kB}, {0, 1.5}}).find("in [0, 1]"), std::string::npos);
  EXPECT_NE(problem({{-kA, kB}, {0, 1}}).find("point 1 (d = -0.001 m): the size"), std::string::npos);
  EXPECT_NE(problem({{kA, kB}, {0, 1}}, kA, kB, SizeDistribution::uniform).find("uniform_mass or log_uniform_mass"),
            std::string::npos);
  EXPECT_NE(problem({{kA, kB}, {0, 1}}, 0.5e-3).find("within the curve"), std::string::npos);
  EXPECT_NE(problem({{kA, 1.5e-3, kB}, {0, 0, 1}}, kA, 1.4e-3).find("no mass"), std::string::npos);
  EXPECT_NE(problem({{kA, kB}, {0, 1}}, 1.5e-3, 1.5e-3).find("min and max must differ"), std::string::npos);
  Material m;
  m.size_distribution = SizeDistribution::log_uniform_mass;
  m.grading_curve = {{kA, kB}, {0, 0.9}};
  try {
    m.validate();
    ADD_FAILURE() << "a curve that does not reach 100% was accepted";
  } catch (const ConfigError& e) {
    EXPECT_EQ(e.field(), "material.diameter.grading");
  }
}

}  // namespace
}  // namespace demcal::engine
