#include "calibrate/inversion.hpp"
#include "synthetic.hpp"

#include "jobs/job_error.hpp"

#include <gtest/gtest.h>

#include <cstdio>

namespace demcal::test {
namespace {

using calibrate::Model;
using calibrate::Target;

Model model_of(const calibrate::ResponseSurface& rs) {
  Model m;
  m.metric = rs.metric;
  m.job = rs.job;
  m.surrogate = calibrate::fit_surrogate(rs);
  m.replica_se = rs.replica_se();
  return m;
}

const calibrate::Box kBox{15, 40, 0.0, 0.5};

// One trial: noisy replicated grids of phi_peak and phi_cv, targets from the truth
// (plus a laboratory's noise of sd `lab` when given; `sigma` is what the user states).
struct Trial {
  double theta, eta;
  calibrate::FitResult fit;
  double err_pk, err_cv;  // the surrogates' true errors at the true point
};
Trial trial(std::uint64_t seed, double lab = 0.0, double sigma = calibrate::kNaN) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> ut(18, 37), ue(0.05, 0.45);
  std::normal_distribution<double> n01(0.0, 1.0);
  Trial t;
  t.theta = ut(rng);
  t.eta = ue(rng);
  const auto pk = synthetic_surface(phi_peak_fn, 0.4, 2, rng, "phi_peak");
  const auto cv = synthetic_surface(phi_cv_steep, 0.4, 2, rng, "phi_cv");
  const double pk_true = phi_peak_fn(t.theta, t.eta), cv_true = phi_cv_steep(t.theta, t.eta);
  std::vector<Target> targets = {{"phi_peak", pk_true + lab * n01(rng), sigma}, {"phi_cv", cv_true + lab * n01(rng), sigma}};
  const std::vector<Model> models = {model_of(pk), model_of(cv)};
  t.fit = calibrate::invert(models, targets, kBox);
  t.err_pk = models[0].surrogate(t.theta, t.eta) - pk_true;
  t.err_cv = models[1].surrogate(t.theta, t.eta) - cv_true;
  return t;
}

TEST(Inversion, RecoversKnownParametersInsideThe95PercentRegion) {
  int covered = 0, ok = 0, covered_theta = 0, covered_eta = 0;
  double worst_theta = 0, worst_eta = 0, err2[2] = {0, 0}, sig[2] = {0, 0};
  const int n = 50;
  for (std::uint64_t seed = 1; seed <= n; ++seed) {
    const Trial t = trial(seed);
    ok += t.fit.ok;
    if (t.fit.region.contains(t.fit.box, t.theta, t.eta)) ++covered;
    covered_theta += t.theta >= t.fit.theta_lo1 && t.theta <= t.fit.theta_hi1;
    covered_eta += t.eta >= t.fit.eta_lo1 && t.eta <= t.fit.eta_hi1;
    worst_theta = std::max(worst_theta, std::abs(t.fit.theta - t.theta));
    worst_eta = std::max(worst_eta, std::abs(t.fit.eta - t.eta));
    err2[0] += t.err_pk * t.err_pk / n;
    err2[1] += t.err_cv * t.err_cv / n;
    sig[0] += t.fit.targets[0].sigma / n;
    sig[1] += t.fit.targets[1].sigma / n;
  }
  std::printf("true point inside the 95%% region in %d of %d trials; largest error theta %.3g deg, eta %.3g\n", covered, n,
              worst_theta, worst_eta);
  std::printf("sigma used / true surrogate error at the truth (RMS): phi_peak %.3g / %.3g, phi_cv %.3g / %.3g\n", sig[0],
              std::sqrt(err2[0]), sig[1], std::sqrt(err2[1]));
  EXPECT_EQ(ok, n);
  EXPECT_GE(covered, 43);  // >= 85%
  std::printf("per-parameter 95%% intervals hold the true theta in %d, eta in %d of %d\n", covered_theta, covered_eta, n);
  EXPECT_GE(covered_theta, 43);
  EXPECT_GE(covered_eta, 43);
  EXPECT_LT(worst_theta, 5.0);
  EXPECT_LT(worst_eta, 0.1);
  // Honest, not merely safe: the stated sigma is the surrogate's real error within a
  // factor (the replica noise counted twice, as before, made it 2.7-4.2x and the
  // region ~5x too large in area).
  for (int k = 0; k < 2; ++k) {
    EXPECT_GT(sig[k], 0.8 * std::sqrt(err2[k])) << k;
    EXPECT_LT(sig[k], 2.2 * std::sqrt(err2[k])) << k;
  }
}

TEST(Inversion, ALaboratorysUncertaintyAddsToTheSurrogatesAndTheCoverageCheckCanFail) {
  // Targets measured with noise (sd 1 deg): unstated, the region is about the
  // surrogate's error only and misses the truth (so the coverage check above can
  // fail); stated with --sigma, it adds to the surrogate's error and covers again.
  int unstated = 0, stated = 0;
  for (std::uint64_t seed = 1; seed <= 50; ++seed) {
    const Trial a = trial(seed, 1.0);
    unstated += a.fit.region.contains(a.fit.box, a.theta, a.eta);
    const Trial b = trial(seed, 1.0, 1.0);
    stated += b.fit.region.contains(b.fit.box, b.theta, b.eta);
    const auto& tf = b.fit.targets[0];
    EXPECT_DOUBLE_EQ(tf.lab_sigma, 1.0);
    EXPECT_NEAR(tf.sigma * tf.sigma, 1.0 + tf.surrogate_sigma * tf.surrogate_sigma, 1e-12);
  }
  std::printf("lab noise 1 deg: covered %d of 50 unstated, %d of 50 with --sigma 1\n", unstated, stated);
  EXPECT_LT(unstated, 43);
  EXPECT_GE(stated, 43);
}

TEST(Inversion, ReportsBestPointPredictionsAndRegion) {
  const Trial t = trial(7);
  ASSERT_TRUE(t.fit.ok);
  ASSERT_EQ(t.fit.targets.size(), 2u);
  for (const auto& tf : t.fit.targets) {
    EXPECT_NEAR(tf.residual, tf.predicted - tf.target, 1e-12);
    EXPECT_LT(std::abs(tf.residual), tf.sigma);
    EXPECT_GT(tf.sigma, 0);
  }
  EXPECT_LE(t.fit.region.theta_lo, t.fit.theta);
  EXPECT_GE(t.fit.region.theta_hi, t.fit.theta);
  EXPECT_LE(t.fit.region.eta_lo, t.fit.eta);
  EXPECT_GE(t.fit.region.eta_hi, t.fit.eta);
  // Each parameter's own interval holds the best point and lies within the joint extents.
  const auto& f = t.fit;
  EXPECT_LE(f.region.theta_lo, f.theta_lo1);
  EXPECT_LE(f.theta_lo1, f.theta);
  EXPECT_LE(f.theta, f.theta_hi1);
  EXPECT_LE(f.theta_hi1, f.region.theta_hi);
  EXPECT_LE(f.region.eta_lo, f.eta_lo1);
  EXPECT_LE(f.eta_lo1, f.eta);
  EXPECT_LE(f.eta, f.eta_hi1);
  EXPECT_LE(f.eta_hi1, f.region.eta_hi);
  EXPECT_LT(f.theta_hi1 - f.theta_lo1, f.region.theta_hi - f.region.theta_lo);
  const auto j = t.fit.to_json();
  EXPECT_EQ(j["intervals"]["theta_deg"][0].get<double>(), f.theta_lo1);
  EXPECT_EQ(j["status"], "ok");
  EXPECT_TRUE(j.contains("theta_deg"));
}

TEST(Inversion, OneTargetForTwoUnknownsWarns) {
  std::mt19937_64 rng(3);
  const auto pk = synthetic_surface(phi_peak_fn, 0.3, 2, rng, "phi_peak");
  const auto fit = calibrate::invert({model_of(pk)}, {{"phi_peak", phi_peak_fn(28, 0.2)}}, kBox);
  ASSERT_TRUE(fit.ok);
  bool curve = false;
  for (const auto& w : fit.warnings) curve = curve || w.find("one target for two unknowns") != std::string::npos;
  EXPECT_TRUE(curve);
}

TEST(Inversion, PhiCvFlatInThetaWarnsThatThetaIsNotPinned) {
  std::mt19937_64 rng(4);
  const auto cv = synthetic_surface(phi_cv_flat, 0.2, 2, rng, "phi_cv");
  const auto fit = calibrate::invert({model_of(cv)}, {{"phi_cv", phi_cv_flat(32, 0.2)}}, kBox);
  ASSERT_TRUE(fit.ok);
  bool theta = false;
  for (const auto& w : fit.warnings) {
    std::printf("warning: %s\n", w.c_str());
    theta = theta || w.find("theta") != std::string::npos;
  }
  EXPECT_TRUE(theta);
  EXPECT_TRUE(fit.region.at_theta_hi);
}

TEST(Inversion, UnreachableTargetNamesTheMetricAndTheBound) {
  std::mt19937_64 rng(5);
  const auto pk = synthetic_surface(phi_peak_fn, 0.3, 2, rng, "phi_peak");
  const auto cv = synthetic_surface(phi_cv_fn, 0.3, 2, rng, "phi_cv");
  // Above anything the grid reaches.
  auto fit = calibrate::invert({model_of(pk), model_of(cv)}, {{"phi_peak", 70.0}, {"phi_cv", 32.0}}, kBox);
  EXPECT_FALSE(fit.ok);
  ASSERT_FALSE(fit.unreachable.empty());
  std::printf("unreachable: %s\n", fit.unreachable.front().c_str());
  EXPECT_NE(fit.unreachable.front().find("phi_peak = 70"), std::string::npos);
  EXPECT_NE(fit.unreachable.front().find("above"), std::string::npos);
  EXPECT_NE(fit.unreachable.front().find("theta upper bound"), std::string::npos);
  EXPECT_FALSE(fit.to_json().contains("theta_deg"));  // no answer presented
  // Below.
  fit = calibrate::invert({model_of(pk)}, {{"phi_peak", 5.0}}, kBox);
  EXPECT_FALSE(fit.ok);
  ASSERT_FALSE(fit.unreachable.empty());
  EXPECT_NE(fit.unreachable.front().find("below"), std::string::npos);
  EXPECT_NE(fit.unreachable.front().find("theta lower bound"), std::string::npos);
  // Each reachable alone, not together inside the box: the best point sits on a bound.
  const double pk_lo = phi_peak_fn(15, 0.0);
  fit = calibrate::invert({model_of(pk), model_of(cv)}, {{"phi_peak", pk_lo + 0.5, 0.2}, {"phi_cv", 34.5, 0.2}}, kBox);
  EXPECT_FALSE(fit.ok);
  ASSERT_FALSE(fit.unreachable.empty());
  std::printf("unreachable: %s\n", fit.unreachable.front().c_str());
  EXPECT_NE(fit.unreachable.front().find("misses phi_"), std::string::npos);
  EXPECT_FALSE(fit.to_json().contains("theta_deg"));
}

// Beyond the grid's values, but within reach of its sigma: an answer, on the grid's
// edge, with a warning that the target is not met there (a repose target 3.7 deg above
// the grid's highest angle, 1.5 sigma, read as matched without a word).
TEST(Inversion, ATargetJustBeyondTheGridIsAnsweredWithAWarning) {
  std::mt19937_64 rng(5);
  const auto pk = synthetic_surface(phi_peak_fn, 0.3, 2, rng, "phi_peak");
  const double top = phi_peak_fn(kBox.theta_hi, kBox.eta_hi);
  const auto fit = calibrate::invert({model_of(pk)}, {{"phi_peak", top + 0.8, 1.0}}, kBox);
  ASSERT_TRUE(fit.ok) << (fit.unreachable.empty() ? "" : fit.unreachable.front());
  bool said = false;
  for (const auto& w : fit.warnings)
    said = said || (w.rfind("phi_peak = ", 0) == 0 && w.find(" is above anything the grid reaches (at most ") != std::string::npos &&
                    w.find(" deg, at ") != std::string::npos);
  EXPECT_TRUE(said);
  const auto inside = calibrate::invert({model_of(pk)}, {{"phi_peak", top - 3.0, 1.0}}, kBox);
  for (const auto& w : inside.warnings) EXPECT_EQ(w.find("anything the grid reaches"), std::string::npos) << w;
}

TEST(ReplicaCorrelation, PoolsTheDeviationsOfReplicasPairedByTask) {
  calibrate::ResponseSurface a, b;
  a.job = b.job = "j";
  auto point = [](std::vector<std::int64_t> tasks, std::vector<double> values) {
    calibrate::GridPoint p;
    p.tasks = std::move(tasks);
    p.values = std::move(values);
    return p;
  };
  // b lists the first point's replicas in another order and lacks task 6.
  a.points = {point({1, 2, 3}, {1, 2, 3}), point({4, 5, 6}, {0, 1, 5}), point({7, 8, 9}, {0, 0, 3})};
  b.points = {point({3, 1, 2}, {6, 2, 4}), point({4, 5}, {3, 1}), point({7, 8, 9}, {1, 1, 1})};
  // Pairs (1,2) (2,4) (3,6); (0,3) (1,1); (0,1) (0,1) (3,1): sums of deviation
  // products 4 - 1 + 0, of squares 2 + 0.5 + 6 and 8 + 2 + 0; 2 + 1 + 2 dof.
  auto c = calibrate::replica_correlation(a, b);
  ASSERT_TRUE(c.estimated) << c.reason;
  EXPECT_NEAR(c.rho, 3.0 / std::sqrt(8.5 * 10.0), 1e-12);
  EXPECT_EQ(c.dof, 5);
  EXPECT_EQ(c.points, 3);
  // Too few degrees of freedom: not estimated, and the reason says so.
  b.points.pop_back();
  c = calibrate::replica_correlation(a, b);
  EXPECT_FALSE(c.estimated);
  EXPECT_EQ(c.rho, 0.0);
  EXPECT_NE(c.reason.find("3 dof"), std::string::npos) << c.reason;
  // Different jobs are different packings.
  b.job = "other";
  c = calibrate::replica_correlation(a, a);
  EXPECT_TRUE(c.estimated);
  EXPECT_NEAR(c.rho, calibrate::kMaxCorrelation, 1e-15);  // a metric with itself: capped below 1
  c = calibrate::replica_correlation(a, b);
  EXPECT_FALSE(c.estimated);
  EXPECT_NE(c.reason.find("different jobs"), std::string::npos);
}

TEST(ReplicaCorrelation, RecoversTheNoiseCorrelationOfASyntheticGrid) {
  for (const double rho : {0.0, 0.3, 0.6}) {
    double sum = 0;
    for (std::uint64_t seed = 1; seed <= 10; ++seed) {
      std::mt19937_64 rng(seed);
      const auto [pk, cv] = synthetic_pair(phi_peak_fn, phi_cv_steep, 0.5, rho, 3, rng);
      const auto c = calibrate::replica_correlation(pk, cv);
      ASSERT_TRUE(c.estimated);
      EXPECT_EQ(c.dof, 72);
      EXPECT_NEAR(c.rho, rho, 0.35) << seed;  // one estimate from 72 dof: sd ~0.1
      sum += c.rho;
    }
    std::printf("true rho %.2f: mean estimate over 10 grids %.3f\n", rho, sum / 10);
    EXPECT_NEAR(sum / 10, rho, 0.08);
  }
}

// Targets at the truth of correlated grids, fitted with and without the correlation.
struct CorrelatedTrial {
  double theta, eta;
  calibrate::FitResult with, without;
  std::vector<Model> models;
};
CorrelatedTrial correlated_trial(std::uint64_t seed, double rho) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> ut(18, 37), ue(0.05, 0.45);
  CorrelatedTrial t;
  t.theta = ut(rng);
  t.eta = ue(rng);
  const auto [pk, cv] = synthetic_pair(phi_peak_fn, phi_cv_steep, 0.4, rho, 2, rng);
  const std::vector<Target> targets = {{"phi_peak", phi_peak_fn(t.theta, t.eta)}, {"phi_cv", phi_cv_steep(t.theta, t.eta)}};
  t.models = {model_of(pk), model_of(cv)};
  t.with = calibrate::invert(t.models, targets, kBox, {}, {{0, 1, calibrate::replica_correlation(pk, cv)}});
  t.without = calibrate::invert(t.models, targets, kBox);
  return t;
}

TEST(Inversion, CorrelatedTargetsUseTheFullCovariance) {
  const CorrelatedTrial t = correlated_trial(11, 0.8);
  const auto& f = t.with;
  ASSERT_TRUE(f.ok);
  ASSERT_EQ(f.correlations.size(), 1u);
  ASSERT_TRUE(f.correlations[0].c.estimated);
  const double rho = f.correlations[0].c.rho;
  EXPECT_GT(rho, 0.5);
  // The noise part of each surrogate's sigma, and the misfit as r' C^-1 r by hand.
  for (std::size_t k = 0; k < 2; ++k) {
    const auto& tf = f.targets[k];
    EXPECT_NEAR(tf.noise_sigma, std::sqrt(t.models[k].surrogate.mean_leverage()) * tf.replica_se, 1e-15);
    EXPECT_LE(tf.noise_sigma, tf.surrogate_sigma);
  }
  const double s0 = f.targets[0].sigma, s1 = f.targets[1].sigma;
  // At the best point the surrogates' noise is correlated by rho times the cosine
  // between their hat vectors.
  const auto h0 = t.models[0].surrogate.hat(f.theta, f.eta), h1 = t.models[1].surrogate.hat(f.theta, f.eta);
  const double cosine = h0.dot(h1) / (h0.norm() * h1.norm());
  EXPECT_NEAR(f.correlations[0].at_best, rho * cosine, 1e-12);
  EXPECT_LE(std::abs(cosine), 1.0 + 1e-12);
  const double c01 = rho * cosine * f.targets[0].noise_sigma * f.targets[1].noise_sigma;
  const double r0 = f.targets[0].residual, r1 = f.targets[1].residual;
  const double det = s0 * s0 * s1 * s1 - c01 * c01;
  EXPECT_NEAR(f.misfit, (r0 * r0 * s1 * s1 - 2 * r0 * r1 * c01 + r1 * r1 * s0 * s0) / det, 1e-9 * (1 + f.misfit));
  const auto j = f.to_json();
  EXPECT_EQ(j["correlations"][0]["metrics"][1], "phi_cv");
  EXPECT_DOUBLE_EQ(j["correlations"][0]["rho"].get<double>(), rho);
  // A correlation of 0 is the independent fit, exactly.
  calibrate::PairCorrelation zero{0, 1, {}};
  zero.c.estimated = true;
  const std::vector<Target> targets = {{"phi_peak", f.targets[0].target}, {"phi_cv", f.targets[1].target}};
  const auto z = calibrate::invert(t.models, targets, kBox, {}, {zero});
  EXPECT_EQ(z.theta, t.without.theta);
  EXPECT_EQ(z.eta, t.without.eta);
  EXPECT_EQ(z.misfit, t.without.misfit);
  EXPECT_EQ(z.region.mask, t.without.region.mask);
  EXPECT_THROW(calibrate::invert(t.models, targets, kBox, {}, {{1, 0, {}}}), std::invalid_argument);
}

TEST(Inversion, CountingTheReplicaCorrelationKeepsTheRegionsCoverage) {
  // phi_peak and phi_cv from the same packings err together (rho 0.9 here, 0.33
  // measured on the seed study): both rise with theta, so a shared error reads as a
  // shift in theta that the independent misfit does not expect.
  int with = 0, without = 0, with1 = 0, without1 = 0;
  double area_with = 0, area_without = 0;
  const int n = 50;
  const double rho = 0.9;
  for (std::uint64_t seed = 1; seed <= n; ++seed) {
    const CorrelatedTrial t = correlated_trial(seed, rho);
    ASSERT_TRUE(t.with.ok);
    with += t.with.region.contains(t.with.box, t.theta, t.eta);
    without += t.without.region.contains(t.without.box, t.theta, t.eta);
    with1 += t.theta >= t.with.theta_lo1 && t.theta <= t.with.theta_hi1;
    without1 += t.theta >= t.without.theta_lo1 && t.theta <= t.without.theta_hi1;
    area_with += t.with.region.cells;
    area_without += t.without.region.cells;
  }
  std::printf("rho %.2f: 95%% region covers the truth %d / %d times counting the correlation, %d / %d ignoring it; "
              "theta interval %d / %d against %d / %d; region area ratio %.2f\n",
              rho, with, n, without, n, with1, n, without1, n, area_with / area_without);
  EXPECT_GE(with, 43);
  EXPECT_GE(with1, 43);
}

TEST(Inversion, InconsistentPairwiseCorrelationsAreDroppedWithAWarning) {
  std::mt19937_64 rng(21);
  const auto [pk, cv] = synthetic_pair(phi_peak_fn, phi_cv_steep, 0.4, 0.0, 2, rng);
  std::vector<Model> models = {model_of(pk), model_of(cv), model_of(cv)};
  models[2].metric = "phi_cv_copy";
  // Replica noise large enough to be all of each surrogate's sigma: then pairwise
  // correlations of +0.95, +0.95 and -0.95 make no covariance matrix.
  for (auto& m : models) m.replica_se = 3.0;
  const double th = 28, et = 0.2;
  const std::vector<Target> targets = {
      {"phi_peak", phi_peak_fn(th, et)}, {"phi_cv", phi_cv_steep(th, et)}, {"phi_cv_copy", phi_cv_steep(th, et)}};
  auto pair = [](std::size_t k, std::size_t l, double rho) {
    calibrate::PairCorrelation p{k, l, {}};
    p.c.rho = rho;
    p.c.estimated = true;
    return p;
  };
  const auto f = calibrate::invert(models, targets, kBox, {}, {pair(0, 1, 0.95), pair(0, 2, 0.95), pair(1, 2, -0.95)});
  bool warned = false;
  for (const auto& w : f.warnings) warned = warned || w.find("not consistent") != std::string::npos;
  EXPECT_TRUE(warned);
  for (const auto& pc : f.correlations) EXPECT_FALSE(pc.c.estimated);
  const auto independent = calibrate::invert(models, targets, kBox);
  EXPECT_EQ(f.misfit, independent.misfit);
}

TEST(Inversion, ParsesTargetsAndSigmas) {
  auto t = calibrate::parse_target("phi_peak=41.4");
  EXPECT_EQ(t.metric, "phi_peak");
  EXPECT_DOUBLE_EQ(t.value, 41.4);
  EXPECT_THROW(calibrate::parse_target("phi_peak"), jobs::JobError);
  EXPECT_THROW(calibrate::parse_target("phi_peak=abc"), jobs::JobError);
  EXPECT_THROW(calibrate::parse_target("=3"), jobs::JobError);
  EXPECT_THROW(calibrate::parse_target("phi peak=3"), jobs::JobError);
  EXPECT_THROW(calibrate::parse_target("phi_peak=0x29"), jobs::JobError);  // not hexadecimal
  EXPECT_THROW(calibrate::parse_target("phi_peak= 41"), jobs::JobError);
  std::vector<Target> ts = {t};
  calibrate::apply_sigma(ts, "phi_peak=0.5");
  EXPECT_DOUBLE_EQ(ts[0].sigma, 0.5);
  EXPECT_THROW(calibrate::apply_sigma(ts, "phi_cv=0.5"), jobs::JobError);
  EXPECT_THROW(calibrate::apply_sigma(ts, "phi_peak=-1"), jobs::JobError);
  // Given twice, under either name: refused, not the last value silently kept.
  try {
    calibrate::apply_sigma(ts, "phi_peak_deg=2");
    FAIL() << "a second --sigma for phi_peak was taken";
  } catch (const jobs::JobError& e) {
    EXPECT_NE(std::string(e.what()).find("given twice"), std::string::npos) << e.what();
  }
  EXPECT_DOUBLE_EQ(ts[0].sigma, 0.5);
  std::vector<Target> other = {calibrate::parse_target("phi_cv=30")};
  calibrate::apply_sigma(other, "phi_cv_deg=0.7");  // the stored name of the same metric
  EXPECT_DOUBLE_EQ(other[0].sigma, 0.7);
  std::vector<Target> diff = {calibrate::parse_target("phi_diff=5")};
  calibrate::apply_sigma(diff, "phi_diff_deg=1");  // the scene's stored difference
  EXPECT_DOUBLE_EQ(diff[0].sigma, 1.0);
}

}  // namespace
}  // namespace demcal::test
