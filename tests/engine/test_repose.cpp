// The repose scene (seed Sec. 2.2.4) and its profile measurement.
#include "engine/errors.hpp"
#include "engine/packing.hpp"
#include "engine/repose_profile.hpp"
#include "engine/scenes/repose.hpp"

#include <gtest/gtest.h>

#include <algorithm>

#include <cmath>
#include <cstdio>
#include <random>

using namespace demcal::engine;

namespace {

// A heap sloping down towards +x at `angle_deg`: crest plateau up to x_crest,
// height h0 there, toe where the line meets the floor.
double heap_height(double x, double angle_deg, double h0, double x_crest) {
  if (x <= x_crest) return h0;
  return std::max(0.0, h0 - std::tan(deg_to_rad(angle_deg)) * (x - x_crest));
}

// Small, soft, cheap column: a few hundred grains, stiffness scaled down 1000x
// (overlaps stay below 2 % of a radius under this column's weight and impacts).
ReposeConfig cheap(double theta_deg, double eta) {
  ReposeConfig c;
  c.material.friction_angle = deg_to_rad(theta_deg);
  c.material.rolling_eta = eta;
  c.column_width = 0.015;
  c.column_height = 0.015;
  c.slab_depth_diameters = 3.0;
  c.stiffness_scale = 1e-3;
  c.time_limit = 1.5;
  // Seed 7 with the batched pair kernel (rounding differs from the scalar one) left
  // the eta = 0.3 deposit still, front fixed from 0.3 s, yet rocking on its undamped
  // rolling springs: flow kinetic energy 4e-13..8e-12 J against the 7.7e-13 J rest
  // threshold until 2.5 s, so "not settled", as designed. Seeds 8 and 9 rest by 0.4 s.
  c.seed = 8;
  c.threads = 1;
  return c;
}

void report(const char* label, const ReposeResult& r) {
  std::printf("[ report   ] %s: status %s, repose %.1f +- %.1f deg, steepest %.1f deg, runout ratio %.2f, "
              "height %.4f m, rest at %.3f s, %ld grains, %.1f s wall\n",
              label, to_string(r.outcome.status), r.repose_deg, r.repose_fit_err_deg, r.steepest_deg,
              r.runout_ratio, r.final_height_m, r.time_to_rest_s, r.particles, r.wall_seconds);
}

}  // namespace

// ---- profile measurement: pure functions ----------------------------------

TEST(ReposeProfile, LineThroughTriangularHeapRecoversItsSlope) {
  for (double angle : {15.0, 31.3, 45.0}) {
    std::vector<double> x, h;
    for (double xi = 0.0005; xi < 0.15; xi += 0.001) {
      x.push_back(xi);
      h.push_back(heap_height(xi, angle, 0.03, 0.02));
    }
    const SlopeFit f = fit_slope(x, h, 0.2, 0.8);
    ASSERT_TRUE(f.ok) << f.why;
    EXPECT_NEAR(f.angle_deg, angle, 1e-6);
    EXPECT_LT(f.slope, 0.0);
    EXPECT_NEAR(f.h_max, 0.03, 1e-12);
    EXPECT_LT(f.angle_err_deg, 1e-6);
    EXPECT_NEAR(steepest_angle_deg(x, h, f.x_upper, f.x_lower, 5), angle, 1e-6);
  }
}

TEST(ReposeProfile, AngleErrorIsTheSlopeErrorCarriedThroughTheArctangent) {
  // A 40 deg heap with alternating +-0.3 mm bumps: the slope has a standard error,
  // and the angle's is that error seen through atan (a central difference here, not
  // the formula the fit uses): at 40 deg it is 0.59 of the slope's, in radians.
  std::vector<double> x, h;
  int k = 0;
  for (double xi = 0.0005; xi < 0.15; xi += 0.001, ++k) {
    x.push_back(xi);
    h.push_back(heap_height(xi, 40.0, 0.03, 0.02) + (k % 2 ? 3e-4 : -3e-4));
  }
  const SlopeFit f = fit_slope(x, h, 0.2, 0.8);
  ASSERT_TRUE(f.ok) << f.why;
  ASSERT_GT(f.slope_se, 0.0);
  const double s = std::abs(f.slope), ds = 1e-3 * f.slope_se;
  const double through_atan = (std::atan(s + ds) - std::atan(s - ds)) / (2.0 * ds) * f.slope_se * 180.0 / M_PI;
  EXPECT_NEAR(f.angle_err_deg / through_atan, 1.0, 1e-6);
  EXPECT_NEAR(f.angle_err_deg / (f.slope_se * 180.0 / M_PI), 1.0 / (1.0 + s * s), 1e-6);
  EXPECT_LT(f.angle_err_deg, 0.7 * f.slope_se * 180.0 / M_PI);
}

TEST(ReposeProfile, HeapBuiltOfGrainsGivesItsSlopeWithinHalfADegree) {
  // Polydisperse grains (d in [1, 2] mm) filling a 31.3 deg heap 40 mm high: each
  // column of the heap is stacked from the floor up until the next grain would
  // stick out of the surface line. The profile is the grains' upper envelope.
  const double angle = 31.3, h0 = 0.04, x_crest = 0.02;
  std::mt19937_64 rng(3);
  std::vector<Vec3> pos;
  std::vector<double> rad;
  for (double x = 0.001; x < 0.12; x += 0.0015) {
    for (double y = 0.001; y < 0.006; y += 0.002) {
      const double xs = x + uniform(rng, -0.0003, 0.0003);
      const double top = heap_height(xs, angle, h0, x_crest);
      double z = 0.0;
      while (true) {
        const double r = 0.5 * uniform(rng, 0.001, 0.002);
        if (z + 2 * r > top) break;
        pos.push_back(Vec3(xs, y, z + r));
        rad.push_back(r);
        z += 2 * r;
      }
    }
  }
  const SurfaceProfile prof = surface_profile(pos, rad, nullptr, 0.0, 0.12, 0.0015, 0.0);
  const SlopeFit f = fit_slope(prof.x, prof.h, 0.2, 0.8);
  ASSERT_TRUE(f.ok) << f.why;
  std::printf("[ report   ] grain heap of %.1f deg: fitted %.2f +- %.2f deg over %d bins, steepest %.1f deg\n", angle,
              f.angle_deg, f.angle_err_deg, f.points,
              steepest_angle_deg(prof.x, prof.h, f.x_upper, f.x_lower, 5));
  EXPECT_NEAR(f.angle_deg, angle, 0.5);
  EXPECT_GT(f.points, 20);
  EXPECT_GT(f.angle_err_deg, 0.0);
}

TEST(ReposeProfile, FitExcludesCrestAndToe) {
  // A heap with a steep 60 deg lip at the crest and a flat 5 deg toe apron: the
  // 0.2-0.8 band only sees the 30 deg flank.
  std::vector<double> x, h;
  for (double xi = 0.0005; xi < 0.2; xi += 0.001) {
    double hi;
    if (xi < 0.01) hi = 0.05;
    else if (xi < 0.01 + 0.005 / std::tan(deg_to_rad(60))) hi = 0.05 - std::tan(deg_to_rad(60)) * (xi - 0.01);
    else {
      const double x1 = 0.01 + 0.005 / std::tan(deg_to_rad(60));
      hi = 0.045 - std::tan(deg_to_rad(30)) * (xi - x1);
      if (hi < 0.006) {
        const double x2 = x1 + (0.045 - 0.006) / std::tan(deg_to_rad(30));
        hi = std::max(0.0, 0.006 - std::tan(deg_to_rad(5)) * (xi - x2));
      }
    }
    x.push_back(xi);
    h.push_back(hi);
  }
  const SlopeFit f = fit_slope(x, h, 0.2, 0.8);
  ASSERT_TRUE(f.ok);
  EXPECT_NEAR(f.angle_deg, 30.0, 0.3);
}

// A concave heap (seed Fig. 2.15's error bars are two measurements at different places
// on the slope): 30 deg above half its height, 20 deg below. The whole-range fit lies
// between; the halves recover each flank, and the fit's error is no longer the few
// hundredths of a degree a straight-line regression claims for a curved profile.
TEST(ReposeProfile, UpperAndLowerHalvesOfAConcaveHeapReadTheirOwnAngles) {
  const double h0 = 0.04, x_crest = 0.01, t30 = std::tan(deg_to_rad(30.0)), t20 = std::tan(deg_to_rad(20.0));
  const double x_knee = x_crest + 0.5 * h0 / t30;
  std::vector<double> x, h;
  for (double xi = 0.0005; xi < 0.2; xi += 0.001) {
    double hi = h0;
    if (xi > x_crest) hi = h0 - t30 * (xi - x_crest);
    if (xi > x_knee) hi = 0.5 * h0 - t20 * (xi - x_knee);
    x.push_back(xi);
    h.push_back(std::max(0.0, hi));
  }
  const SlopeFit f = fit_slope(x, h, 0.2, 0.8);
  ASSERT_TRUE(f.ok) << f.why;
  EXPECT_NEAR(f.upper_angle_deg, 30.0, 0.5);  // bins straddling the knee pull a little
  EXPECT_NEAR(f.lower_angle_deg, 20.0, 0.5);
  EXPECT_GT(f.angle_deg, 21.0);
  EXPECT_LT(f.angle_deg, 29.0);
  std::printf("[ report   ] concave heap: fit %.2f +- %.2f deg, upper %.2f, lower %.2f\n", f.angle_deg, f.angle_err_deg,
              f.upper_angle_deg, f.lower_angle_deg);
  // Residuals of one sign for many bins in a row: 1.17 deg, where the plain regression
  // error, which takes them as independent, claims 0.33.
  EXPECT_GT(f.angle_err_deg, 0.8);
  // A half with fewer than 6 bins has no angle.
  // A 45 deg heap in 5 mm bins: 7 bins in the fit, 4 in each half.
  std::vector<double> cx, ch;
  for (int i = 0; i <= 10; ++i) {
    cx.push_back(0.005 * i);
    ch.push_back(0.05 - 0.005 * i);
  }
  const SlopeFit coarse = fit_slope(cx, ch, 0.2, 0.8);
  ASSERT_TRUE(coarse.ok) << coarse.why;
  EXPECT_EQ(coarse.points, 7);
  EXPECT_NEAR(coarse.angle_deg, 45.0, 1e-9);
  EXPECT_TRUE(std::isnan(coarse.upper_angle_deg));
  EXPECT_TRUE(std::isnan(coarse.lower_angle_deg));
}

TEST(ReposeProfile, FrontIgnoresDetachedBouncers) {
  std::vector<Vec3> pos;
  std::vector<double> rad;
  for (int i = 0; i < 40; ++i) {  // a deposit up to x = 0.04 m
    pos.push_back(Vec3(0.001 * i + 0.0005, 0.0, 0.002));
    rad.push_back(0.0005);
  }
  pos.push_back(Vec3(0.07, 0.0, 0.0005));  // a lone grain far ahead
  rad.push_back(0.0005);
  const SurfaceProfile prof = surface_profile(pos, rad, nullptr, 0.0, 0.1, 0.001, 0.0);
  const Front f = deposit_front(prof, 0, 0.0004, 3, &pos, &rad);
  EXPECT_NEAR(f.x, 0.04, 1e-9);
  const Front g = deposit_front(prof, 0, 0.0004, 40, &pos, &rad);  // gap allowed: the grain counts
  EXPECT_NEAR(g.x, 0.0705, 1e-9);
}

TEST(ReposeProfile, AGrainInFlightBeyondTheFrontDoesNotDerailTheFit) {
  // The seed study's eta = 0 slab: a straight 20 deg heap, and far beyond its front a
  // grain in mid-air as high as 88% of the crest (it rolled on and bounced off the end
  // wall). The fit over the whole profile started at that grain and found no slope.
  std::vector<Vec3> pos;
  std::vector<double> rad;
  const double r = 0.0005, slope = std::tan(20.0 * kPi / 180.0), h0 = 0.03;
  for (double x = r; h0 - slope * x > r; x += 2 * r)
    for (double z = r; z <= h0 - slope * x; z += 2 * r) {
      pos.push_back(Vec3(x, 0.0, z));
      rad.push_back(r);
    }
  pos.push_back(Vec3(0.2, 0.0, 0.88 * h0));
  rad.push_back(r);
  const SurfaceProfile prof = surface_profile(pos, rad, nullptr, 0.0, 0.25, 2 * r, 0.0);
  const Front front = deposit_front(prof, 0, r, 3, &pos, &rad);
  EXPECT_LT(front.x, 0.1);
  EXPECT_FALSE(fit_slope(prof.x, prof.h, 0.2, 0.8).ok);  // what the scene did
  const SlopeFit f = fit_heap(prof, front, 0.2, 0.8);
  ASSERT_TRUE(f.ok) << f.why;
  EXPECT_NEAR(f.angle_deg, 20.0, 1.0);
}

TEST(ReposeProfile, MotionCarriersTellAFewRattlersFromAFlow) {
  // 200 grains creeping at 1 mm/s and 3 rattlers at 10 cm/s: the rattlers carry 98%.
  std::vector<Vec3> v(203, Vec3(1e-3, 0.0, 0.0));
  std::vector<double> m(203, 1e-6);
  std::vector<std::uint8_t> include(203, 1);
  for (int k : {17, 90, 150}) v[k] = Vec3(0.0, 0.0, k == 90 ? -0.12 : 0.1);
  include[5] = 0;
  v[5] = Vec3(5.0, 0.0, 0.0);  // a fixed floor grain: not counted, however fast
  MotionCarriers c = motion_carriers(v, m, include);
  EXPECT_EQ(c.grains, 202u);
  EXPECT_EQ(c.carriers, 3u);
  EXPECT_EQ(c.fastest, 90);
  // Everyone at the same speed: 90% of the energy takes 90% of the grains.
  for (auto& u : v) u = Vec3(0.0, 1e-2, 0.0);
  c = motion_carriers(v, m, include);
  EXPECT_EQ(c.carriers, 182u);  // ceil(0.9 * 202)
  // Nothing moving: no carriers.
  for (auto& u : v) u = Vec3::Zero();
  EXPECT_EQ(motion_carriers(v, m, include).carriers, 0u);
  EXPECT_EQ(motion_carriers(v, m, include).fastest, -1);
}

TEST(ReposeProfile, AHeapIsStillThoughAGrainHopsAtItsToeButNotWhileItsToeCreeps) {
  // 100 samples over 0.5 s, the angle steady; the front at 29.1 mm but for a grain
  // hopping 3.8 or 10 mm beyond it for single samples (as a quick repose heap
  // measured), one of them the window's last.
  std::vector<double> t, front, angle;
  for (int i = 0; i < 100; ++i) {
    t.push_back(1.0 + 0.005 * i);
    front.push_back(0.0291);
    angle.push_back(24.0 + 1e-7 * i);
  }
  front[2] = front[40] = 0.0329;
  front[99] = 0.0391;
  HeapStillness h = heap_stillness(t, front, angle, 1.0, 0.4);
  ASSERT_TRUE(h.judged) << h.why;
  EXPECT_EQ(h.since, 1.0);
  EXPECT_EQ(h.front_change_m, 0.0);
  EXPECT_NEAR(h.front_excursion_m, 0.0100, 1e-12);
  EXPECT_NEAR(h.angle_change_deg, 99e-7, 1e-12);

  // A grain bouncing beyond the toe every few samples, about half of the time (as
  // another heap measured): the toe has not moved.
  for (int i = 0; i < 100; ++i) front[i] = i % 5 < 2 ? 0.0355 : 0.0317;
  h = heap_stillness(t, front, angle, 1.0, 0.4);
  ASSERT_TRUE(h.judged);
  EXPECT_EQ(h.front_change_m, 0.0);
  EXPECT_NEAR(h.front_excursion_m, 0.0038, 1e-12);

  // A toe creeping by 3 mm across the window moves its lower envelope by 2.5 mm (from
  // the first sample of the first sixth to that of the last), hops or not.
  for (int i = 0; i < 100; ++i) front[i] = 0.0291 + 0.003 * i / 99.0 + (i % 5 < 2 ? 0.0038 : 0.0);
  h = heap_stillness(t, front, angle, 1.0, 0.4);
  ASSERT_TRUE(h.judged);
  EXPECT_NEAR(h.front_change_m, 0.003 * 83.0 / 99.0, 1e-4);
  // Still for two thirds of the window, then creeping 3 mm: seen (1.5 mm of it, where
  // the last sixth starts).
  for (int i = 0; i < 100; ++i) front[i] = 0.0291 + (i < 67 ? 0.0 : 0.003 * (i - 67) / 32.0);
  h = heap_stillness(t, front, angle, 1.0, 0.4);
  EXPECT_NEAR(h.front_change_m, 0.003 * 16.0 / 32.0, 1e-4);
  // A toe that retreats (a grain rolling back) moves it too.
  for (int i = 0; i < 100; ++i) front[i] = i < 50 ? 0.0291 : 0.0275;
  EXPECT_NEAR(heap_stillness(t, front, angle, 1.0, 0.4).front_change_m, 0.0016, 1e-12);

  // Only the window counts; too short a window, or one without a heap, is not judged.
  for (int i = 0; i < 100; ++i) front[i] = 0.0291 + 0.003 * i / 99.0;
  h = heap_stillness(t, front, angle, 1.479, 0.4);  // the last four samples
  ASSERT_TRUE(h.judged) << h.why;
  EXPECT_LT(h.front_change_m, 0.0003);
  EXPECT_EQ(heap_stillness(t, front, angle, 1.492, 0.4).why, "its window holds fewer than two samples");
  EXPECT_EQ(heap_stillness(t, front, angle, 0.3, 0.4).why, "its window starts before min_collapse_time");
  angle[50] = NAN;
  EXPECT_NE(heap_stillness(t, front, angle, 1.0, 0.4).why.find("no slope could be fitted"), std::string::npos);
}

TEST(ReposeProfile, AHeapStillByItsProfileIsAtRestFromWhenItStoppedNotFromTheWindow) {
  // Samples every 5 ms to 1.5 s; the angle settles at 24 deg at 0.4 s, the front at
  // 0.3 s; the run judged the last 0.5 s still.
  std::vector<double> t, front, angle;
  for (int i = 0; i <= 300; ++i) {
    const double ti = 0.005 * i;
    t.push_back(ti);
    front.push_back(ti < 0.3 ? 0.02 + 0.03 * ti : 0.029);
    angle.push_back(ti < 0.4 ? 30.0 - 15.0 * ti : 24.0);
  }
  // Within 0.5 deg of 24 from 0.4 - 0.5/15 s, the first sample after it 0.37 s.
  EXPECT_NEAR(still_since(t, front, angle, 0.5, 0.05, 0.5, 0.001), 0.37, 1e-9);
  EXPECT_NEAR(still_since(t, front, angle, 0.5, 0.05, 0.1, 0.001), 0.395, 1e-9);
  // Still throughout: from min_collapse_time on, not before.
  const std::vector<double> flat_front(t.size(), 0.029), flat_angle(t.size(), 24.0);
  EXPECT_NEAR(still_since(t, flat_front, flat_angle, 0.5, 0.05, 0.5, 0.001), 0.05, 1e-12);
  // A toe that crept until 0.6 s: the front decides, within a sample of when its
  // lowest value came within the tolerance (0.567 s).
  for (std::size_t i = 0; i < t.size(); ++i) front[i] = t[i] < 0.6 ? 0.02 + 0.03 * t[i] : 0.038;
  EXPECT_NEAR(still_since(t, front, angle, 0.5, 0.05, 0.5, 0.001), 0.57, 1e-9);
  // A grain 5 mm beyond the toe from 0.70 to 0.85 s, a block (1/6 of the window) and
  // more: not still before it ends; for part of a block it is a hop, as in the window.
  for (std::size_t i = 0; i < t.size(); ++i) front[i] = t[i] >= 0.7 - 1e-9 && t[i] <= 0.85 + 1e-9 ? 0.034 : 0.029;
  const double since = still_since(t, front, flat_angle, 0.5, 0.05, 0.5, 0.001);
  EXPECT_GT(since, 0.75);
  EXPECT_LT(since, 0.86);
  // A last window that is not still has no time to rest.
  angle[300] = 25.0;
  EXPECT_TRUE(std::isnan(still_since(t, flat_front, angle, 0.5, 0.05, 0.5, 0.001)));
  // A series of a sample a step (a job's tiny repose.sample_interval): 300,000
  // samples in one pass.
  std::vector<double> tl, fl, al;
  for (int i = 0; i <= 300000; ++i) {
    tl.push_back(5e-6 * i);
    fl.push_back(0.029);
    al.push_back(tl.back() < 0.4 ? 30.0 - 15.0 * tl.back() : 24.0);
  }
  EXPECT_NEAR(still_since(tl, fl, al, 0.5, 0.05, 0.5, 0.001), 0.4 - 0.5 / 15.0, 1e-5);
}

TEST(ReposeProfile, ALayerAFlatSlopeAndASlopeAgainstTheEndWallAreDoubted) {
  SlopeFit fit;
  fit.ok = true;
  fit.h_max = 0.010;  // 6.7 diameters of 1.5 mm
  fit.angle_deg = 22.3;
  fit.angle_err_deg = 1.4;
  fit.x_lower = 0.030;
  EXPECT_TRUE(slope_doubts(fit, 0.0015, 0.0015, 0.060, false).empty());
  EXPECT_TRUE(slope_doubts(fit, 0.0015, 0.0015, 0.060, true).empty());  // at the wall, but its foot is far from it
  // The foot within two bins of a wall the grains reached: leaning on it.
  fit.x_lower = 0.0575;
  auto d = slope_doubts(fit, 0.0015, 0.0015, 0.060, true);
  ASSERT_EQ(d.size(), 1u);
  EXPECT_NE(d[0].find("leans on the wall"), std::string::npos) << d[0];
  EXPECT_NE(d[0].find("repose.domain_length"), std::string::npos) << d[0];
  EXPECT_TRUE(slope_doubts(fit, 0.0015, 0.0015, 0.060, false).empty());  // no grain there: a free toe
  // 1.4 diameters high: a layer.
  fit.x_lower = 0.030;
  fit.h_max = 0.0021;
  fit.angle_deg = 0.28;
  fit.angle_err_deg = 0.40;
  d = slope_doubts(fit, 0.0015, 0.0015, 0.060, false);
  ASSERT_EQ(d.size(), 1u);
  EXPECT_NE(d[0].find("1.4 mean diameters high"), std::string::npos) << d[0];
  EXPECT_NE(d[0].find("not a heap"), std::string::npos) << d[0];
  // A heap, but a slope within two standard errors of flat.
  fit.h_max = 0.010;
  d = slope_doubts(fit, 0.0015, 0.0015, 0.060, false);
  ASSERT_EQ(d.size(), 1u);
  EXPECT_NE(d[0].find("not told apart from flat"), std::string::npos) << d[0];
  fit.ok = false;
  EXPECT_TRUE(slope_doubts(fit, 0.0015, 0.0015, 0.060, true).empty());
}

TEST(ReposeProfile, TooFewPointsIsNoFit) {
  const SlopeFit f = fit_slope({0.0, 0.001}, {0.01, 0.0}, 0.2, 0.8);
  EXPECT_FALSE(f.ok);
  EXPECT_FALSE(f.why.empty());
}

// ---- config -------------------------------------------------------------------

TEST(ReposeConfig, ValidateNamesTheField) {
  auto field_of = [](ReposeConfig c) {
    try {
      c.validate();
    } catch (const ConfigError& e) {
      return e.field();
    }
    return std::string("none");
  };
  ReposeConfig ok;
  EXPECT_EQ(field_of(ok), "none");
  ReposeConfig c = ok;
  c.column_width = -1;
  EXPECT_EQ(field_of(c), "repose.column_width");
  c = ok;
  c.slab_depth_diameters = 1.0;  // periodic images would touch
  EXPECT_EQ(field_of(c), "repose.slab_depth_diameters");
  c.side_walls = SideWalls::frictional;  // 1.5 mm between walls: the 2 mm grains do not fit
  EXPECT_EQ(field_of(c), "repose.slab_depth_diameters");
  c.slab_depth_diameters = 2.0;  // 3 mm: too thin for periodic images, fine between walls
  EXPECT_EQ(field_of(c), "none");
  c = ok;
  c.stiffness_scale = 2.0;
  EXPECT_EQ(field_of(c), "numerics.stiffness_scale");
  c = ok;
  c.fit_lo = 0.9;
  EXPECT_EQ(field_of(c), "repose.fit_fractions");
  c = ok;
  c.time_limit = 0;
  EXPECT_EQ(field_of(c), "repose.time_limit");
  c = ok;
  c.collapse_drag = -1.0;
  EXPECT_EQ(field_of(c), "repose.collapse_drag");
  c = ok;
  c.rest_profile_window = -0.1;
  EXPECT_EQ(field_of(c), "repose.rest_profile_window");
  c = ok;
  c.bin_width = 0.5 * c.material.d_min;  // bins left empty between grains' centres
  EXPECT_EQ(field_of(c), "repose.bin_width");
  c.bin_width = c.material.d_min;
  EXPECT_EQ(field_of(c), "none");
  c = ok;
  c.rest_profile_tol_deg = 0.0;
  EXPECT_EQ(field_of(c), "repose.rest_profile_tol_deg");
  c = ok;
  c.threads = 0;
  EXPECT_EQ(field_of(c), "threads");
}

// ---- the scene, small and soft -------------------------------------------------

// A column between side walls in a thin slab cannot be filled at random at a solid
// fraction random insertion does not reach there (at depth 1.4 the default 0.33 failed
// for a quick job's seed 1 and passed for seed 8; 0.38 fails): the failure names the
// keys that would let it.
TEST(ReposeScene, AColumnTooThinToFillNamesItsKeys) {
  ReposeConfig c = cheap(30.0, 0.1);
  c.side_walls = SideWalls::frictional;
  c.slab_depth_diameters = 1.4;
  c.fill_solid_fraction = 0.38;  // the most validate() accepts
  try {
    run_repose(c);
    FAIL() << "a 1.4-diameter slab between walls filled at solid fraction " << c.fill_solid_fraction;
  } catch (const ConfigError& e) {
    EXPECT_EQ(e.field(), "repose.fill_solid_fraction");
    EXPECT_NE(std::string(e.what()).find("between side walls, which leave less room): a lower fill_solid_fraction or "
                                         "a deeper slab"),
              std::string::npos)
        << e.what();
  }
}

TEST(ReposeScene, TimeLimitGivesNotSettledAndNoAngle) {
  ReposeConfig c = cheap(30.0, 0.1);
  c.time_limit = 0.03;  // the column is still falling
  const ReposeResult r = run_repose(c);
  EXPECT_EQ(r.outcome.status, SceneStatus::not_settled);
  EXPECT_EQ(r.outcome.failed_stage, "collapse");
  EXPECT_NE(r.outcome.message.find("not at rest"), std::string::npos) << r.outcome.message;
  // The default 0.5 s window does not fit a 0.03 s collapse, and the message says so.
  EXPECT_NE(r.outcome.message.find("profile was not judged: its window starts before min_collapse_time"),
            std::string::npos) << r.outcome.message;
  // The whole column is falling: not blamed on a few rattlers.
  EXPECT_EQ(r.outcome.message.find("rattlers"), std::string::npos) << r.outcome.message;
  for (const auto& [k, v] : r.metrics()) {
    EXPECT_NE(k, "repose_deg");
    EXPECT_NE(k, "runout_m");
  }
  EXPECT_FALSE(r.energy.rows.empty());
  for (const Series* s : {&r.energy, &r.prep, &r.profile})  // HDF5 writes one unit per column
    EXPECT_EQ(s->units.size(), s->columns.size()) << s->name;
  // What the cost forecast counts before a run: every floor grain, a column no smaller
  // than levelling kept, and a run to its limits takes no more steps than that bound.
  const ReposeConfig::GrainEstimate g = c.grain_estimate();
  EXPECT_EQ(g.floor, static_cast<double>(r.floor_particles));
  EXPECT_GE(g.column, static_cast<double>(r.particles));
  EXPECT_LT(g.column, 1.3 * static_cast<double>(r.particles));
  EXPECT_GT(r.steps, 0);
  EXPECT_LE(static_cast<double>(r.steps), c.max_steps());
}

// Which packing keeps rattlers to the time limit, and which heap has a slope to judge
// at a given moment, depend on the trajectory, and so on the rounding of the build
// (-march=native on another CPU, or -DDEMCAL_NATIVE=OFF): the next two tests try a
// few seeds and judge every run whose premise holds, and at least one must hold.
TEST(ReposeScene, AHeapStillButForRattlersIsJudgedByItsProfile) {
  // A few grains bouncing in the rough floor's hollows keep the flow kinetic energy above
  // the rest threshold to the time limit, undamped as the seed's law is, while the heap
  // itself has stopped. With no grain left out of the energy check (rest_trim 0), seed 1
  // at eta = 0.3 does so in the SSE2, AVX2 and AVX-512 builds.
  int judged = 0;
  for (const std::uint64_t seed : {1, 2, 3, 4}) {
    ReposeConfig c = cheap(30.0, 0.3);
    c.seed = seed;
    c.rest_trim = 0.0;  // no grain left out of the energy check: one rattler keeps it up
    const ReposeResult r = run_repose(c);
    report(("rattlers, profile, seed " + std::to_string(seed)).c_str(), r);
    if (!r.outcome.ok()) continue;  // a heap still creeping at the limit: not this test's premise
    if (r.energy.rows.back()[r.energy.column("ke_flow_per_grain")] <= r.rest_ke_J) {
      EXPECT_FALSE(r.rest_by_profile) << "at rest by its energy: the profile is not needed";
      continue;  // no rattlers in this packing
    }
    ++judged;
    EXPECT_TRUE(r.rest_by_profile);
    EXPECT_LE(r.profile_angle_change_deg, c.rest_profile_tol_deg);
    EXPECT_LE(r.profile_front_change_m, r.bin_width);
    // At rest from the earliest time the angle and front held still, at the latest
    // from the window's start; the angle moves no more than the tolerance after it.
    EXPECT_LE(r.time_to_rest_s, c.time_limit - c.rest_profile_window + 2 * c.sample_interval);
    EXPECT_GE(r.time_to_rest_s, c.min_collapse_time);
    double lo = INFINITY, hi = -INFINITY;
    for (const auto& row : r.energy.rows)
      if (row[r.energy.column("time")] >= r.time_to_rest_s) {
        lo = std::min(lo, row[r.energy.column("repose_deg")]);
        hi = std::max(hi, row[r.energy.column("repose_deg")]);
      }
    EXPECT_LE(hi - lo, c.rest_profile_tol_deg);
    ASSERT_EQ(r.outcome.warnings.size(), 1u);
    EXPECT_NE(r.outcome.warnings[0].find("at rest by its profile"), std::string::npos) << r.outcome.warnings[0];
    EXPECT_NE(r.outcome.warnings[0].find("rattlers"), std::string::npos) << r.outcome.warnings[0];
    // The angle is the one the final profile gives, and the series' last row agrees.
    EXPECT_TRUE(std::isfinite(r.repose_deg));
    EXPECT_NEAR(r.energy.rows.back()[r.energy.column("repose_deg")], r.repose_deg, 1e-9);
    bool flagged = false;
    for (const auto& [k, v] : r.metrics()) flagged |= k == "rest_by_profile" && v == 1.0;
    EXPECT_TRUE(flagged);
    break;
  }
  EXPECT_EQ(judged, 1) << "no seed left rattlers at the time limit";
}

TEST(ReposeScene, AHeapStillFlowingIsNotJudgedAtRestByItsProfile) {
  int judged = 0;
  for (const std::uint64_t seed : {8, 9, 10}) {
    ReposeConfig c = cheap(30.0, 0.1);
    c.seed = seed;
    c.time_limit = 0.15;  // the column is still spreading
    c.rest_profile_window = 0.05;
    const ReposeResult r = run_repose(c);
    report(("flowing, profile, seed " + std::to_string(seed)).c_str(), r);
    EXPECT_EQ(r.outcome.status, SceneStatus::not_settled) << r.outcome.message;
    EXPECT_FALSE(r.rest_by_profile);
    // Early in the window the spreading heap may have no slope to fit yet: then the
    // message says the profile was not judged, and another seed is tried.
    if (r.outcome.message.find("the heap's profile was not judged") != std::string::npos) continue;
    ++judged;
    EXPECT_GT(r.profile_front_change_m + r.profile_angle_change_deg, 0.0);
    EXPECT_NE(r.outcome.message.find("the heap's angle moved by"), std::string::npos) << r.outcome.message;
    break;
  }
  EXPECT_EQ(judged, 1) << "no seed gave a heap whose profile could be judged";
}

// A column a few grains across (5-6 mm: ~20-34 grains) leaves a heap whose "slope"
// is a line through a handful of bins: the angle is reported, with a warning that it
// is no measurement. How many bins a heap this small spans depends on its trajectory
// (the 6 mm heap spans 5 on one CPU and 6 on another), so each heap is judged by its
// own count, and at least one must fall short. (The cheap 15 mm column passes:
// FrictionRaisesTheAngle... checks.)
TEST(ReposeScene, AHeapTooSmallForASlopeIsWarned) {
  const auto warned = [](const ReposeResult& x) {
    return std::any_of(x.outcome.warnings.begin(), x.outcome.warnings.end(),
                       [](const std::string& w) {
                         return w.find("profile bins, fewer than 6") != std::string::npos ||
                                w.find("no angle of repose") != std::string::npos;  // one bin or none
                       });
  };
  int too_few = 0;
  for (const double width : {0.005, 0.006}) {
    ReposeConfig c = cheap(30.0, 0.1);
    c.column_width = c.column_height = width;
    const ReposeResult r = run_repose(c);
    report((std::to_string(static_cast<int>(width * 1000 + 0.5)) + " mm column").c_str(), r);
    if (!r.outcome.ok()) {  // no slope at all: no result (the trajectory is the CPU's)
      EXPECT_EQ(r.outcome.status, SceneStatus::invalid) << r.outcome.message;
      EXPECT_EQ(r.outcome.message.rfind("no angle of repose: ", 0), 0u) << r.outcome.message;
      ++too_few;
      continue;
    }
    EXPECT_EQ(warned(r), r.fit_points < ReposeResult::kMinSlopeBins) << width << ": " << r.fit_points << " bins";
    too_few += r.fit_points < ReposeResult::kMinSlopeBins;
  }
  EXPECT_GE(too_few, 1);
}

TEST(ReposeScene, FrictionRaisesTheAngleAndRollingResistanceRaisesItFurther) {
  // theta = eta = 0 dissipates nothing in the seed's law; a background viscous
  // drag in the collapse lets it come to rest (recorded as collapse_drag).
  ReposeConfig c0 = cheap(0.0, 0.0);
  c0.collapse_drag = 15.0;
  c0.time_limit = 2.5;
  const ReposeResult r0 = run_repose(c0);
  report("theta 0, eta 0  ", r0);
  const ReposeResult r1 = run_repose(cheap(30.0, 0.0));
  report("theta 30, eta 0 ", r1);
  const ReposeResult r2 = run_repose(cheap(30.0, 0.3));
  report("theta 30, eta .3", r2);

  ASSERT_TRUE(r0.outcome.ok()) << r0.outcome.message;
  ASSERT_TRUE(r1.outcome.ok()) << r1.outcome.message;
  ASSERT_TRUE(r2.outcome.ok()) << r2.outcome.message;
  EXPECT_LT(r0.repose_deg, 15.0);
  EXPECT_GT(r0.runout_ratio, r1.runout_ratio);
  EXPECT_GT(r0.runout_ratio, 1.5);
  EXPECT_GT(r1.repose_deg, r0.repose_deg + 5.0);
  EXPECT_GT(r2.repose_deg, r1.repose_deg);
  EXPECT_GE(r2.final_height_m, r1.final_height_m * 0.95);
  // Recorded knobs.
  EXPECT_DOUBLE_EQ(r2.stiffness_scale, 1e-3);
  EXPECT_NEAR(r2.kn, 3e4, 1e-6);
  EXPECT_GT(r2.dt, 0.0);
  EXPECT_LT(r2.dt, r2.dt_critical);
  EXPECT_NE(r2.boundaries.find("periodic"), std::string::npos);
  EXPECT_GT(r2.particles, 100);
  EXPECT_NEAR(r2.column_height, 0.015, 0.001);
  for (const ReposeResult* r : {&r1, &r2}) {  // a slope, not a line through a few bins
    EXPECT_GE(r->fit_points, ReposeResult::kMinSlopeBins);
    for (const auto& w : r->outcome.warnings) EXPECT_EQ(w.find("profile bins, fewer than"), std::string::npos) << w;
  }
}

TEST(ReposeScene, FrictionalSideWallsSteepenTheDeposit) {
  // A narrow channel with frictional walls holds a steeper heap than the periodic
  // slab (wall friction carries part of the slope's weight; Taberlet et al. 2003).
  // The 20 mm column: on the 15 mm one the fit error (~5 deg between walls) is as
  // large as the effect. Seed 1 measured 23.8 deg periodic, 32.4 deg walled.
  ReposeConfig c = cheap(30.0, 0.1);
  c.column_width = c.column_height = 0.02;
  c.seed = 1;
  const ReposeResult periodic = run_repose(c);
  report("periodic slab     ", periodic);
  c.side_walls = SideWalls::frictional;
  const ReposeResult walled = run_repose(c);
  report("frictional walls  ", walled);
  ASSERT_TRUE(periodic.outcome.ok()) << periodic.outcome.message;
  ASSERT_TRUE(walled.outcome.ok()) << walled.outcome.message;
  EXPECT_GT(walled.repose_deg, periodic.repose_deg + 4.0);
  EXPECT_LT(walled.runout_ratio, periodic.runout_ratio);
  EXPECT_NE(walled.boundaries.find("frictional side walls"), std::string::npos) << walled.boundaries;
  const Particles& p = walled.final_particles;
  for (std::size_t i = 0; i < p.size(); ++i) {
    EXPECT_GT(p.x[i][1], 0.0) << "grain " << i << " left through the y = 0 wall";
    EXPECT_LT(p.x[i][1], walled.slab_depth_m) << "grain " << i << " left through the far wall";
  }
}

// A deposit at rest whose profile gave no fit reports the rest of its measurements
// but nothing of the fit: no angle, error, halves or steepest angle that would read 0.
TEST(ReposeResultMetrics, NoFitMeansNoAngleMetricsButTheRest) {
  ReposeResult r;
  r.repose_deg = NAN;
  r.runout_ratio = 1.2;
  const Metrics m = r.metrics();
  auto has = [&](const std::string& k) {
    return std::any_of(m.begin(), m.end(), [&](const auto& kv) { return kv.first == k; });
  };
  for (const char* k : {"repose_deg", "repose_fit_err_deg", "steepest_deg", "fit_points", "repose_upper_deg",
                        "repose_lower_deg"})
    EXPECT_FALSE(has(k)) << k;
  EXPECT_TRUE(has("runout_ratio"));
  EXPECT_TRUE(has("time_to_rest_s"));
  r.repose_deg = 24.0;
  const Metrics fitted = r.metrics();
  for (const char* k : {"repose_deg", "repose_upper_deg", "repose_lower_deg", "steepest_deg"})
    EXPECT_TRUE(std::any_of(fitted.begin(), fitted.end(), [&](const auto& kv) { return kv.first == k; })) << k;
}
