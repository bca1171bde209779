#include "calibrate/metric.hpp"
#include "calibrate/surrogate.hpp"
#include "synthetic.hpp"

#include <gtest/gtest.h>

#include <cstdio>
#include <set>

namespace demcal::test {
namespace {

struct Accuracy {
  double rms = 0, max = 0;
};

Accuracy accuracy(const calibrate::Surrogate& s, const Fn& f) {
  std::mt19937_64 rng(99);
  std::uniform_real_distribution<double> ut(15, 40), ue(0, 0.5);
  Accuracy a;
  const int n = 2000;
  for (int i = 0; i < n; ++i) {
    const double th = ut(rng), et = ue(rng), e = s(th, et) - f(th, et);
    a.rms += e * e;
    a.max = std::max(a.max, std::abs(e));
  }
  a.rms = std::sqrt(a.rms / n);
  return a;
}

TEST(Surrogate, ReproducesAnAnalyticSurfaceWithinItsLooError) {
  std::mt19937_64 rng(1);
  const auto rs = synthetic_surface(phi_peak_fn, 0.0, 1, rng);
  const auto s = calibrate::fit_surrogate(rs);
  const Accuracy a = accuracy(s, phi_peak_fn);
  std::printf("noise-free phi_peak surface, 36 points: %s; true RMS error %.4g, max %.4g\n", s.describe().c_str(), a.rms, a.max);
  EXPECT_GT(s.loo_rms(), 0.0);
  // LOO is an estimate of the prediction error, not a bound: within 25% of it over
  // the whole box, and no point off by more than 3 times it.
  EXPECT_LE(a.rms, 1.25 * s.loo_rms());
  EXPECT_LE(a.max, 3 * s.loo_rms());
  EXPECT_LT(s.loo_rms(), 0.5);  // a smooth surface over a 6 x 6 grid: well below a degree
  // Data points are reproduced closely.
  for (const auto& p : rs.points) EXPECT_NEAR(s(p.theta, p.eta), p.mean, 3 * s.loo_rms());
}

TEST(Surrogate, NoisyDataAreSmoothedAndTheLooErrorCoversTheTruth) {
  std::mt19937_64 rng(2);
  const auto rs = synthetic_surface(phi_peak_fn, 0.5, 2, rng);
  const auto s = calibrate::fit_surrogate(rs);
  const Accuracy a = accuracy(s, phi_peak_fn);
  std::printf("noisy (sd 0.5, 2 replicas): %s; true RMS error %.4g; replica se %.3g\n", s.describe().c_str(), a.rms, rs.replica_se());
  EXPECT_LE(a.rms, s.loo_rms());
  // Absolute anchors, not only against its own estimate: smoothing must beat the raw
  // data (a 2-replica mean carries noise 0.5 / sqrt 2 = 0.354), and the LOO error
  // stays near that noise (it includes it), not far above.
  EXPECT_LT(a.rms, 0.354);
  EXPECT_LT(s.loo_rms(), 0.6);
  EXPECT_NEAR(rs.pooled_sd, 0.5, 0.2);
  // Smoothing chosen: not an interpolant of the noise.
  EXPECT_FALSE(s.kind() == calibrate::SurrogateKind::thin_plate && s.lambda() == 0.0);
}

TEST(Surrogate, IsLinearInItsPointsMeansThroughTheHatVector) {
  // s(x) = hat(x) . y for every kind the fit picks: the spline (interpolating and
  // smoothing) and the polynomials. The inversion's noise correlations rest on it.
  std::set<std::string> kinds;
  const std::vector<std::pair<Fn, double>> cases = {
      {phi_peak_fn, 0.0}, {phi_peak_fn, 0.5}, {[](double th, double et) { return 20 + 0.3 * th + 5 * et - 2 * et * th / 40; }, 0.05},
      {[](double th, double et) { return 1e-4 * th * th * th + et * et * et; }, 0.0}, {phi_cv_fn, 0.0}, {phi_cv_fn, 0.3},
      {[](double th, double et) { return std::abs(th - 27.0) + 10 * std::abs(et - 0.25); }, 0.0}};
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> ut(15, 40), ue(0, 0.5);
  for (const auto& [f, noise] : cases) {
    const auto rs = synthetic_surface(f, noise, 2, rng);
    const auto s = calibrate::fit_surrogate(rs);
    kinds.insert(calibrate::kind_name(s.kind()) + (s.lambda() > 0 ? " smoothed" : ""));
    Eigen::VectorXd y(static_cast<Eigen::Index>(rs.points.size()));
    for (std::size_t i = 0; i < rs.points.size(); ++i) y(static_cast<Eigen::Index>(i)) = rs.points[i].mean;
    for (int i = 0; i < 50; ++i) {
      const double th = ut(rng), et = ue(rng);
      EXPECT_NEAR(s.hat(th, et).dot(y), s(th, et), 1e-9 * (1 + std::abs(s(th, et)))) << s.describe();
    }
    EXPECT_TRUE(s.same_points(s));
  }
  for (const auto& k : kinds) std::printf("hat vector checked for: %s\n", k.c_str());
  EXPECT_GE(kinds.size(), 3u);
}

TEST(Surrogate, RefusesPointsThatCannotCarryASurface) {
  EXPECT_THROW(calibrate::fit_surrogate({15, 20, 25}, {0.1, 0.1, 0.1}, {1, 2, 3}, {1, 1, 1}, {15, 25, 0, 0.5}),
               std::invalid_argument);
  EXPECT_THROW(calibrate::fit_surrogate({15, 20, 25, 30}, {0.1, 0.1, 0.1, 0.1}, {1, 2, 3, 4}, {1, 1, 1, 1}, {15, 30, 0, 0.5}),
               std::invalid_argument);
}

}  // namespace
}  // namespace demcal::test

// A metric's unit, for map titles and the surrogate's error: the four angles, and a
// stored name by its suffix; none for a pure number.
TEST(Metric, AStoredMetricIsLabelledWithTheUnitItsNameEndsWith) {
  EXPECT_EQ(demcal::calibrate::metric_spec("phi_cv").unit, "deg");
  EXPECT_EQ(demcal::calibrate::metric_spec("phi_cv_deg").label, "phi_cv (deg)");
  EXPECT_EQ(demcal::calibrate::metric_spec("phi_cv_se_deg").label, "phi_cv_se_deg (deg)");
  EXPECT_EQ(demcal::calibrate::metric_spec("q_peak_pa").unit, "Pa");
  EXPECT_EQ(demcal::calibrate::metric_spec("wall_s").unit, "s");
  EXPECT_EQ(demcal::calibrate::metric_spec("drift_per_simulated_s").unit, "1/s");
  EXPECT_EQ(demcal::calibrate::metric_spec("particle_steps_per_s").unit, "1/s");
  EXPECT_EQ(demcal::calibrate::metric_spec("wall_s_per_simulated_s").unit, "");
  EXPECT_EQ(demcal::calibrate::metric_spec("porosity_final").label, "porosity_final");
  EXPECT_EQ(demcal::calibrate::metric_spec("porosity_final").unit, "");
}
