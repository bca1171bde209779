// System-level checks: conservation laws, neighbour search against brute force,
// history across rebuilds, determinism, time-step refusal, instability detection
// and the Love-Weber stress.
#include "engine/errors.hpp"
#include "engine/measure.hpp"
#include "engine/packing.hpp"
#include "engine/scenes/collision.hpp"
#include "engine/timestep.hpp"
#include "engine/world.hpp"
#include "test_util.hpp"

#include <set>
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>

using namespace demcal::engine;
using namespace demcal::engine::testing;

namespace {

// A random cloud of n grains (diameters in [1, 2] mm) at solid fraction phi.
Particles cloud(std::size_t n, double phi, std::uint64_t seed, double vmax, Vec3* hi_out,
                std::array<bool, 3> periodic = {false, false, false}) {
  std::mt19937_64 rng(seed);
  auto radii = sample_radii(n, 1e-3, 2e-3, rng);
  double vs = 0;
  for (double r : radii) vs += sphere_volume(r);
  const double edge = std::cbrt(vs / phi);
  Particles p;
  insert_random(p, radii, Vec3::Zero(), Vec3::Constant(edge), kDensity, rng, periodic);
  for (std::size_t i = 0; i < p.size(); ++i) {
    for (int a = 0; a < 3; ++a) {
      p.v[i][a] = uniform(rng, -vmax, vmax);
      p.w[i][a] = uniform(rng, -vmax, vmax) / p.r[i];
    }
  }
  *hi_out = Vec3::Constant(edge);
  return p;
}

// 300 grains placed at solid fraction 0.35, then grown by 6%: many contacts from the
// first step, none deep enough to trip the overlap check. The domain is the box
// [0, hi] they were placed in.
struct CrowdedBox {
  Particles p;
  Domain dom;
};
CrowdedBox crowded_box() {
  CrowdedBox box;
  box.p = cloud(300, 0.35, 11, 0.5, &box.dom.hi);
  for (std::size_t i = 0; i < box.p.size(); ++i) box.p.r[i] *= 1.06;
  return box;
}

// Sum of |tangential spring| + |rolling spring| over the live contacts (walls only,
// or all): nonzero when a frictional stage has left history.
double spring_total(const World& w, bool walls_only) {
  double total = 0.0;
  w.for_each_contact([&](const ContactView& c) {
    if (!walls_only || c.wall >= 0) total += c.fs.norm() + c.mr.norm();
  });
  return total;
}

double safe_dt(double factor = 0.1) { return factor * std::sqrt(mass_of(0.5e-3) / 3e7); }

Vec3 momentum(const Particles& p) {
  Vec3 s = Vec3::Zero();
  for (std::size_t i = 0; i < p.size(); ++i) s += p.m[i] * p.v[i];
  return s;
}
Vec3 angular_momentum(const Particles& p) {
  Vec3 s = Vec3::Zero();
  for (std::size_t i = 0; i < p.size(); ++i)
    s += p.x[i].cross(p.m[i] * p.v[i]) + 0.4 * p.m[i] * p.r[i] * p.r[i] * p.w[i];
  return s;
}

}  // namespace

TEST(Conservation, FreeCloudKeepsLinearAndAngularMomentum) {
  Vec3 hi;
  Particles p = cloud(300, 0.35, 7, 1.0, &hi);
  Domain dom;
  dom.hi = hi;
  World w(std::move(p), {}, dom, law(3e7, 2.7e7, 30.0, 1.0, 0.3), options(safe_dt()));
  const Vec3 p0 = momentum(w.particles()), l0 = angular_momentum(w.particles());
  long contacts_seen = 0;
  for (int k = 0; k < 400; ++k) {
    w.run(10);
    contacts_seen += coordination(w).contacts;
  }
  ASSERT_GT(contacts_seen, 100) << "the test needs collisions to mean anything";
  const double pscale = 300 * mass_of(0.75e-3) * 1.0, lscale = pscale * hi.norm();
  EXPECT_LT((momentum(w.particles()) - p0).norm() / pscale, 1e-12);
  EXPECT_LT((angular_momentum(w.particles()) - l0).norm() / lscale, 1e-12);
}

TEST(Conservation, NewtonsThirdLawPerContact) {
  // Two grains in an oblique, sliding, rolling contact: the forces on them are
  // equal and opposite and the torques balance the moment of the force pair.
  Particles p;
  p.add(Vec3(0, 0, 0), 1e-3, kDensity);
  p.add(Vec3(1.99e-3, 0.3e-4, 0.1e-4), 0.9999e-3, kDensity);
  p.v[0] = Vec3(0.01, 0.2, -0.1);
  p.w[1] = Vec3(50, -20, 80);
  World w(std::move(p), {}, open_domain(), law(3e7, 2.7e7, 30.0, 1.0, 0.2), options(safe_dt()));
  w.run(3);
  const Particles& q = w.particles();
  ASSERT_GT(q.f[0].norm(), 0.0);
  EXPECT_LT((q.f[0] + q.f[1]).norm(), 1e-14 * q.f[0].norm());
  const Vec3 moment = q.x[0].cross(q.f[0]) + q.x[1].cross(q.f[1]) + q.t[0] + q.t[1];
  EXPECT_LT(moment.norm(), 1e-12 * q.f[0].norm() * 1e-3);
}

TEST(Conservation, WorkOfAMovingWallIsTheEnergyItGives) {
  // A frictionless wall driven at constant speed into a grain at rest, no gravity:
  // all the wall's work goes into the grain's kinetic energy and the contact spring.
  // Returns the worst mismatch over the push, relative to the work done.
  auto mismatch = [](double dt_factor) {
    Particles p;
    p.add(Vec3(0.0, 0.0, 1.0e-3), 1.0e-3, kDensity);  // touching the floor z = 0
    std::vector<Wall> walls = {plane("floor", Vec3::Zero(), Vec3(0, 0, 1))};
    walls[0].velocity = Vec3(0.0, 0.0, 0.05);
    World w(std::move(p), walls, open_domain(), law(3e7, 0.0), options(safe_dt(dt_factor)));
    const long steps = std::lround(1000 * 0.1 / dt_factor);  // the same 21 µs of push and flight
    double worst = 0.0, largest = 0.0;
    for (long k = 0; k < steps; ++k) {
      w.run(1);
      const Energies e = energies(w);
      worst = std::max(worst, std::abs(w.wall_work() - (e.kinetic() + e.elastic())));
      largest = std::max(largest, w.wall_work());
    }
    EXPECT_GT(largest, 0.0) << "the wall must have pushed";
    EXPECT_GT(w.particles().v[0].z(), 0.05) << "and launched the grain (it leaves faster than the wall)";
    return worst / largest;
  };
  const double coarse = mismatch(0.1), fine = mismatch(0.05);
  std::printf("[ report   ] wall work against kinetic + elastic energy: worst mismatch %.3g (dt 0.1), %.3g (dt 0.05)\n",
              coarse, fine);
  EXPECT_LT(coarse, 3e-4);
  // The trapezoid rule on the wall's power and velocity Verlet are second order in dt.
  EXPECT_LT(fine, 0.35 * coarse);
}

TEST(Conservation, LocalDampingScalesAFallingGrainsAccelerationBy1MinusAlpha) {
  // Cundall's local damping opposes each force component along the velocity:
  // a grain falling freely from rest accelerates at g (1 - alpha), exactly.
  for (double alpha : {0.0, 0.3, 0.7}) {
    Particles p;
    p.add(Vec3(0.0, 0.0, 0.0), 1.0e-3, kDensity);
    WorldOptions o = options(safe_dt());
    o.gravity = Vec3(0.0, 0.0, -9.81);
    o.local_damping = alpha;
    World w(std::move(p), {}, open_domain(), law(3e7, 0.0), o);
    w.run(10);
    const double v0 = w.particles().v[0].z();
    w.run(100);
    const double a = (w.particles().v[0].z() - v0) / (100 * safe_dt());
    EXPECT_NEAR(a, -9.81 * (1.0 - alpha), 1e-6 * 9.81) << "alpha " << alpha;
  }
}


TEST(Measurements, UnbalancedForceRatioIgnoresLocalDamping) {
  // Damping rescales each force component by 1 -+ alpha along the motion: it hides
  // an imbalance, it does not remove one. The same crowded, moving, frictional box
  // under gravity reads the same ratio with damping 0, 0.3 and 0.7 (on 1 and 2
  // threads), while the forces the integrator uses differ.
  const CrowdedBox box = crowded_box();
  std::vector<Wall> walls = box_walls(Vec3::Zero(), box.dom.hi);
  auto ratio = [&](double alpha, int threads, std::vector<Vec3>* forces) {
    WorldOptions o = options(safe_dt(), threads);
    o.gravity = Vec3(0.0, 0.0, -9.81);
    o.local_damping = alpha;
    World w(box.p, walls, box.dom, law(3e7, 2.7e7, 30.0, 1.0, 0.2), o);
    w.refresh();
    *forces = w.particles().f;
    return unbalanced_force_ratio(w);
  };
  std::vector<Vec3> plain, damped;
  const double ufr = ratio(0.0, 1, &plain);
  EXPECT_GT(ufr, 0.05);  // far from equilibrium: the check has something to compare
  double total = 0.0;
  for (const Vec3& f : plain) total += f.norm();
  for (double alpha : {0.3, 0.7})
    for (int threads : {1, 2}) {
      EXPECT_NEAR(ratio(alpha, threads, &damped), ufr, 1e-12 * ufr) << "alpha " << alpha << ", threads " << threads;
      double moved = 0.0;  // how much damping changed the forces the integrator uses
      for (std::size_t i = 0; i < plain.size(); ++i) moved += (damped[i] - plain[i]).norm();
      EXPECT_GT(moved, 0.5 * alpha * total) << "alpha " << alpha;
    }
}

TEST(Measurements, AFixedGrainBeyondAWallIsNoContact) {
  // Walls exert nothing on fixed grains (a rough floor's grains beyond a gate's plane):
  // the measurements must not count what the forces do not exert. A fixed grain three
  // radii behind a wall's plane and a free grain pressed into it.
  const double r = 0.5e-3;
  Particles p;
  p.add(Vec3(0.0, 0.0, -3.0 * r), r, kDensity, /*is_fixed=*/true);
  p.add(Vec3(0.01, 0.0, 0.999 * r), r, kDensity);
  Wall floor;
  floor.name = "floor";
  World w(std::move(p), {floor}, open_domain(), law(3e7, 2.7e7, 30.0, 1.0, 0.1), options(safe_dt()));
  w.refresh();
  int contacts = 0;
  w.for_each_contact([&](const ContactView& c) {
    ++contacts;
    EXPECT_EQ(c.i, 1) << "the fixed grain is in no contact";
  });
  EXPECT_EQ(contacts, 1);
  EXPECT_EQ(w.walls()[0].contacts, 1);
  // The free grain's overlap, 0.001 r (4e-6 J), is the only elastic energy: the fixed
  // grain's 4 r with the plane would read 0.5 kn (2 mm)^2 = 60 J.
  EXPECT_NEAR(energies(w).normal, 0.5 * 3e7 * std::pow(1e-3 * r, 2), 1e-9);
}

TEST(Conservation, ContactAcrossThePeriodicSeamActsAsInTheMiddle) {
  // The same oblique, sliding, rolling pair twice: straddling the periodic seam in x,
  // and unwrapped in the middle of the box. The seam must change nothing: the same
  // forces, torques and motion, and momentum kept.
  const double L = 10e-3;
  Domain dom;
  dom.hi = Vec3::Constant(L);
  dom.periodic = {true, false, false};
  auto run = [&](double xa, double xb, Vec3* p_out) {
    Particles p;
    p.add(Vec3(xa, 5e-3, 5e-3), 0.5e-3, kDensity);
    p.add(Vec3(xb, 5.02e-3, 4.99e-3), 0.48e-3, kDensity);
    p.v[0] = Vec3(-1.0, 0.15, -0.05);  // approaching: the contact lasts ~20 steps
    p.w[1] = Vec3(40, -10, 60);
    World w(std::move(p), {}, dom, law(3e7, 2.7e7, 30.0, 1.0, 0.2), options(safe_dt()));
    w.run(10);
    const Particles& q = w.particles();
    *p_out = q.m[0] * q.v[0] + q.m[1] * q.v[1];
    return q;
  };
  Vec3 p_seam, p_mid;
  // Centres 0.9799 mm apart in x across the seam (0.3 mm + 0.6799 mm; with the y and z
  // offsets 0.1 µm of overlap against radii 0.98 mm): a fresh contact.
  const Particles seam = run(0.3e-3, L - 0.6799e-3, &p_seam);
  const Particles mid = run(0.5 * L + 0.3e-3, 0.5 * L - 0.6799e-3, &p_mid);
  ASSERT_GT(mid.f[0].norm(), 0.0) << "the pair must be in contact";
  ASSERT_GT(mid.t[0].norm(), 0.0) << "and sliding or rolling, so that the springs are exercised";
  for (int i = 0; i < 2; ++i) {
    EXPECT_LT((seam.f[i] - mid.f[i]).norm(), 1e-9 * mid.f[0].norm()) << "grain " << i;
    EXPECT_LT((seam.t[i] - mid.t[i]).norm(), 1e-9 * mid.t[0].norm() + 1e-20) << "grain " << i;
    EXPECT_LT((seam.v[i] - mid.v[i]).norm(), 1e-9) << "grain " << i;
    EXPECT_LT((seam.w[i] - mid.w[i]).norm(), 1e-9 * mid.w[1].norm()) << "grain " << i;
  }
  const Vec3 v0(-1.0, 0.15, -0.05);
  const double p0 = mass_of(0.5e-3) * v0.norm();
  EXPECT_LT((p_seam - v0 * mass_of(0.5e-3)).norm(), 1e-12 * p0);
  EXPECT_LT((p_seam - p_mid).norm(), 1e-12 * p0);
}

TEST(NeighbourSearch, FindsExactlyTheOverlapsBruteForceFinds) {
  for (bool periodic : {false, true}) {
    Vec3 hi;
    std::array<bool, 3> per{periodic, periodic, false};
    Particles p = cloud(500, 0.3, 11, 0.0, &hi, per);
    // Inflate the grains so that many of them overlap.
    for (auto& r : p.r) r *= 1.15;
    Domain dom;
    dom.hi = hi;
    dom.periodic = per;
    WorldOptions o = options(safe_dt());
    o.max_overlap_fraction = 1.0;
    World w(p, {}, dom, law(3e7, 0.0), o);
    w.run(1);
    std::set<std::pair<int, int>> brute;  // the same pairs, not only as many
    const Particles& q = w.particles();
    for (std::size_t i = 0; i < q.size(); ++i)
      for (std::size_t j = i + 1; j < q.size(); ++j) {
        Vec3 d = q.x[j] - q.x[i];
        dom.min_image(d);
        if (d.norm() < q.r[i] + q.r[j]) brute.insert({static_cast<int>(i), static_cast<int>(j)});
      }
    std::set<std::pair<int, int>> listed;
    w.for_each_contact([&](const ContactView& c) {
      if (c.j >= 0) {
        EXPECT_TRUE(listed.insert({std::min(c.i, c.j), std::max(c.i, c.j)}).second) << "pair listed twice";
      }
    });
    ASSERT_GT(brute.size(), 50u);
    EXPECT_EQ(listed, brute) << (periodic ? "periodic" : "open");
  }
}

TEST(NeighbourSearch, ContactHistorySurvivesRebuilds) {
  // The same frictional, rolling cloud with a skin so thin that the list is rebuilt
  // nearly every step, and with a generous one: identical trajectories.
  Vec3 hi;
  Particles p = cloud(200, 0.35, 3, 0.5, &hi);
  for (auto& r : p.r) r *= 1.06;  // touching from the start: contacts that last and carry springs
  Domain dom;
  dom.hi = hi;
  std::vector<double> springs;
  auto run = [&](double skin, long* builds) {
    WorldOptions o = options(safe_dt());
    o.skin = skin;
    World w(p, box_walls(Vec3::Zero(), hi), dom, law(3e7, 2.7e7, 30.0, 1.0, 0.2), o);
    w.run(3000);
    *builds = w.neighbors().builds();
    springs.push_back(spring_total(w, false));
    return w.particles().x;
  };
  long b_thin = 0, b_thick = 0;
  const auto x_thin = run(1e-8, &b_thin);
  const auto x_thick = run(4e-4, &b_thick);
  EXPECT_GE(b_thin, 3000) << "the thin skin must rebuild every step";
  EXPECT_GT(b_thin, 20 * b_thick);
  // The springs carried across rebuilds must exist for the comparison to mean anything.
  ASSERT_GT(springs[1], 0.0) << "no tangential or rolling history at the end: nothing was carried";
  EXPECT_NEAR(springs[0], springs[1], 1e-9 * springs[1]);
  double worst = 0;
  for (std::size_t i = 0; i < x_thin.size(); ++i) worst = std::max(worst, (x_thin[i] - x_thick[i]).norm());
  EXPECT_LT(worst, 1e-12);
}

TEST(StageSwitch, FrictionlessStageLeavesNoHistoryToReappear) {
  // Dense preparation: frictional springs, then a frictionless stage (which skips
  // spins and history in the pair loop), then friction again. The frictionless stage
  // must exert no torque, and the last stage must start from fresh springs: it runs
  // exactly as a world built from the same grains with no history at all.
  const auto [p, dom] = crowded_box();
  const ContactParams frictional = law(3e7, 2.7e7, 30.0, 1.0, 0.2);
  World w(p, box_walls(dom.lo, dom.hi), dom, frictional, options(safe_dt()));
  w.run(2000);
  ASSERT_GT(spring_total(w, false), 0.0) << "the first stage must leave history to clear";

  w.set_contact_params(law(3e7, 0.0));
  const std::vector<Vec3> spins = w.particles().w;
  w.run(10);  // short: most contacts of the first stage are still closed
  long contacts = 0;
  w.for_each_contact([&](const ContactView& c) {
    ++contacts;
    EXPECT_EQ(c.fs, Vec3::Zero());
    EXPECT_EQ(c.mr, Vec3::Zero());
  });
  ASSERT_GT(contacts, 20);
  EXPECT_EQ(w.particles().w, spins) << "a frictionless contact exerts no torque";

  World fresh(w.particles(), w.walls(), dom, frictional, options(safe_dt()));
  w.set_contact_params(frictional);
  w.run(1000);
  fresh.run(1000);
  double worst = 0.0;
  for (std::size_t i = 0; i < p.size(); ++i)
    worst = std::max(worst, (w.particles().x[i] - fresh.particles().x[i]).norm());
  EXPECT_LT(worst, 1e-15);
}

TEST(StageSwitch, WallTurnedSmoothDropsItsSpringsAndPushesAlongItsNormal) {
  // Smooth walls have a contact loop of their own (normal spring only). A wall that
  // had friction and rolling resistance keeps no spring once it turns smooth, even
  // for contacts that stay closed across the switch, and pushes along its normal
  // with kn * overlap.
  const auto [p, dom] = crowded_box();
  std::vector<Wall> walls = box_walls(dom.lo, dom.hi);
  for (auto& wall : walls) wall.frictional = wall.rolling = true;
  const double kn = 3e7;
  World w(p, walls, dom, law(kn, 2.7e7, 30.0, 1.0, 0.2), options(safe_dt()));
  w.run(2000);
  ASSERT_GT(spring_total(w, true), 0.0) << "the walls must hold springs before they turn smooth";

  for (auto& wall : w.walls()) wall.frictional = wall.rolling = false;
  w.run(1);  // one step: nearly every wall contact is still the one it was
  long wall_contacts = 0;
  std::vector<Vec3> expected(w.walls().size(), Vec3::Zero());  // force on each wall
  w.for_each_contact([&](const ContactView& c) {
    if (c.wall < 0) return;
    ++wall_contacts;
    EXPECT_EQ(c.fs, Vec3::Zero());
    EXPECT_EQ(c.mr, Vec3::Zero());
    const std::size_t k = static_cast<std::size_t>(c.wall);
    expected[k] -= (kn * c.delta) * w.walls()[k].normal;
  });
  EXPECT_GE(wall_contacts, 3);
  // The force the engine applied, as each wall sums it from its contacts' loop.
  double scale = 0.0;
  for (const Vec3& e : expected) scale = std::max(scale, e.norm());
  ASSERT_GT(scale, 0.0);
  for (std::size_t k = 0; k < expected.size(); ++k)
    EXPECT_LT((w.walls()[k].force - expected[k]).norm(), 1e-12 * scale) << "wall " << k;
}

TEST(Determinism, SameSeedAndThreadsGiveIdenticalRuns) {
  CollisionConfig c;
  c.particles = 200;
  c.steps = 2000;
  c.sample_every = 500;
  c.threads = 2;
  const CollisionResult a = run_collision(c), b = run_collision(c);
  EXPECT_EQ(a.energy_final, b.energy_final);
  ASSERT_GT(a.energy.rows.size(), 3u);
  EXPECT_TRUE(a.energy.rows == b.energy.rows) << "every sample of the series, not only the last";
  c.threads = 1;
  const CollisionResult one = run_collision(c);
  EXPECT_NEAR(one.energy_final / a.energy_final, 1.0, 1e-9);
}

TEST(Determinism, WallsGravityAndDampingAgreeAcrossThreadCounts) {
  // Grain-wall contacts, gravity and local damping run inside the threads' own grain
  // ranges: two threads must reproduce one thread's trajectory and wall forces to
  // rounding, and themselves exactly.
  Vec3 hi;
  const Particles p = cloud(400, 0.3, 5, 2.0, &hi);
  Domain dom;
  dom.hi = hi;
  std::vector<Wall> walls = box_walls(Vec3::Zero(), hi);
  for (auto& w : walls) w.frictional = w.rolling = true;
  auto run = [&](int threads) {
    WorldOptions o = options(safe_dt(), threads);
    o.gravity = Vec3(0.0, 0.0, -9.81);
    o.local_damping = 0.2;
    World w(p, walls, dom, law(3e7, 2.7e7, 30.0, 1.0, 0.2), o);
    long touches = 0;  // grain-wall contacts summed over the steps
    for (int s = 0; s < 4000; ++s) {
      w.step();
      for (const auto& wall : w.walls()) touches += wall.contacts;
    }
    return std::make_pair(std::move(w), touches);
  };
  const auto [one, touches_one] = run(1);
  const auto [two, touches_two] = run(2);
  const auto [again, touches_again] = run(2);
  EXPECT_GT(touches_one, 1000);  // the walls were in play
  EXPECT_EQ(touches_one, touches_two);
  EXPECT_EQ(touches_two, touches_again);
  for (std::size_t k = 0; k < one.walls().size(); ++k) {
    EXPECT_EQ(one.walls()[k].contacts, two.walls()[k].contacts) << one.walls()[k].name;
    EXPECT_LT((one.walls()[k].force - two.walls()[k].force).norm(), 1e-8 * (1.0 + one.walls()[k].force.norm()))
        << one.walls()[k].name;
    EXPECT_EQ(two.walls()[k].force, again.walls()[k].force) << one.walls()[k].name;
  }
  double worst = 0.0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    worst = std::max(worst, (one.particles().x[i] - two.particles().x[i]).norm());
    EXPECT_EQ(two.particles().x[i], again.particles().x[i]);
  }
  EXPECT_LT(worst, 1e-12);
}

TEST(Determinism, MovingWallsAgreeAcrossThreadCounts) {
  // A box squeezed by its six walls: the list is rebuilt and the walls' candidate
  // lists refreshed many times, so a step takes the one-region path (lists kept) and
  // the two-region path (a rebuild) in turn. Two threads must reproduce one thread
  // to rounding, and themselves exactly, wall work included.
  const auto [p, dom] = crowded_box();
  std::vector<Wall> walls = box_walls(dom.lo, dom.hi);
  const double speed = 2.0;  // m/s inward: 0.13 mm (1.3 skins) over the run, 2% of the box
  for (auto& w : walls) {
    w.frictional = w.rolling = true;
    w.velocity = speed * w.normal;  // normals point into the box
  }
  auto run = [&](int threads) {
    World w(p, walls, dom, law(3e7, 2.7e7, 30.0, 1.0, 0.2), options(safe_dt(), threads));
    const Vec3 start = w.walls()[0].point;
    w.run(3000);
    EXPECT_GT((w.walls()[0].point - start).norm(), w.skin());  // the candidates were refreshed
    EXPECT_GT(w.neighbors().builds(), 3);
    return w;
  };
  const World one = run(1), two = run(2), again = run(2);
  EXPECT_GT(std::abs(one.wall_work()), 0.0);
  EXPECT_NEAR(two.wall_work() / one.wall_work(), 1.0, 1e-9);
  EXPECT_EQ(two.wall_work(), again.wall_work());
  EXPECT_EQ(two.neighbors().builds(), one.neighbors().builds());
  double worst = 0.0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    worst = std::max(worst, (one.particles().x[i] - two.particles().x[i]).norm());
    EXPECT_EQ(two.particles().x[i], again.particles().x[i]);
    EXPECT_EQ(two.particles().w[i], again.particles().w[i]);
  }
  // The sums regroup across blocks, and a dense pack amplifies rounding: 1.4e-11 m
  // here after 3,000 steps (3e-8 of a radius). A grain or wall force lost on one
  // path would move grains by orders of magnitude more.
  EXPECT_LT(worst, 1e-9);
}

TEST(Determinism, RowBlocksAgreeWithOneThread) {
  // Pair rows are split into one contiguous block per thread and the threads' force
  // buffers summed after. A crowded box, every grain in contact from the start, on
  // 1 and 3 threads: the same run to rounding (sums regroup across blocks).
  const auto [p, dom] = crowded_box();
  auto run = [&](const Particles& start, const Domain& d, int threads, long steps) {
    World w(start, box_walls(d.lo, d.hi), d, law(3e7, 2.7e7, 30.0, 1.0, 0.2), options(safe_dt(), threads));
    w.run(steps);
    return w.particles();
  };
  const Particles one = run(p, dom, 1, 300), three = run(p, dom, 3, 300);
  double worst = 0.0, moved = 0.0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    worst = std::max(worst, (one.x[i] - three.x[i]).norm());
    moved = std::max(moved, (one.x[i] - p.x[i]).norm());
  }
  EXPECT_GT(moved, 1e-6);  // the contacts pushed the grains apart
  EXPECT_LT(worst, 1e-12);

  // More threads than grains: most blocks are empty; the run is the one-thread run.
  Particles few;
  few.add(Vec3(0.0, 0.0, 0.0), 0.5e-3, kDensity);
  few.add(Vec3(0.95e-3, 0.0, 0.0), 0.5e-3, kDensity);
  few.add(Vec3(1.9e-3, 0.0, 0.0), 0.5e-3, kDensity);
  few.v[0] = Vec3(0.3, 0.1, 0.0);
  Domain box;
  box.lo = Vec3::Constant(-5e-3);
  box.hi = Vec3::Constant(5e-3);
  const Particles a = run(few, box, 1, 1500), b = run(few, box, 4, 1500);
  for (std::size_t i = 0; i < few.size(); ++i) {
    EXPECT_EQ(a.x[i], b.x[i]) << i;
    EXPECT_EQ(a.w[i], b.w[i]) << i;
  }
  EXPECT_NE(a.w[2], Vec3::Zero());  // the contacts had friction
}

TEST(CriticalStep, ClosedFormRatiosForEqualSpheres) {
  LimitInputs in;
  in.law = law(3e7, 2.7e7, 30.0, 1.0, 0.1);
  in.m_min = in.m_max = mass_of(0.5e-3);
  in.r_min = in.r_max = 0.5e-3;
  const StabilityLimits pair = stability_limits(in);
  double normal = 0, tangential = 0;
  for (const auto& m : pair.modes) {
    if (m.mode == "normal") normal = m.dt_critical;
    if (m.mode == "tangential") tangential = m.dt_critical;
  }
  EXPECT_NEAR(normal / tangential, std::sqrt(3.5 * 0.9), 1e-6);  // about 1.77 (issue: "about 1.8x")
  in.has_walls = in.wall_frictional = in.wall_rolling = true;
  const StabilityLimits all = stability_limits(in);
  double wall_normal = 0, wall_fastest = 1e300;
  for (const auto& m : all.modes) {
    if (m.contact != "wall d_min") continue;
    if (m.mode == "normal") wall_normal = m.dt_critical;
    else wall_fastest = std::min(wall_fastest, m.dt_critical);
  }
  // Tangential spring, rotation and rolling spring coupled against a wall: with
  // y = R phi, m x'' = -Ks (x + y) and 0.4 m y'' = -Ks (x + y) - b Ks y; for b = 1 the
  // stiffest eigenvalue is (3 + sqrt(6.5)) Ks/m, so the ratio is sqrt(0.9 (3 + sqrt 6.5)),
  // about 2.23 (issue: "about 2.2x").
  EXPECT_NEAR(wall_normal / wall_fastest, std::sqrt(0.9 * (3.0 + std::sqrt(6.5))), 1e-9);
  // The pair's tangential mode is still the one that governs.
  EXPECT_EQ(all.governing().mode, "tangential");
  EXPECT_EQ(all.governing().contact, "pair d_min-d_min");
}

TEST(CriticalStep, UnequalPairRollsAboutTheMeanRadius) {
  // A d_min-d_max pair (radii 0.5 and 1 mm): in-plane coordinates (x_a, x_b, th_a,
  // th_b); the tangential spring stretches by x_a - x_b + R_a th_a + R_b th_b, the
  // rolling spring, Kr = b Ks r^2 with r = (R_a + R_b) / 2, by th_a - th_b. The
  // fastest in-plane frequency, from M^-1/2 K M^-1/2 written out here, is what the
  // pair's tangential or rolling limit must give; with r = R_b it would be 23% higher.
  const double ra = 0.5e-3, rb = 1e-3, ks = 2.7e7, b = 1.0;
  LimitInputs in;
  in.law = law(3e7, ks, 30.0, b, 0.1);
  in.m_min = mass_of(ra);
  in.r_min = ra;
  in.m_max = mass_of(rb);
  in.r_max = rb;
  const Eigen::Vector4d mass(in.m_min, in.m_max, 0.4 * in.m_min * ra * ra, 0.4 * in.m_max * rb * rb);
  const Eigen::Vector4d gt(1.0, -1.0, ra, rb), gr(0.0, 0.0, 1.0, -1.0);
  const double r = 0.5 * (ra + rb);
  const Eigen::Matrix4d k = ks * gt * gt.transpose() + b * ks * r * r * gr * gr.transpose();
  const Eigen::Vector4d inv_sqrt_m = mass.cwiseSqrt().cwiseInverse();
  const Eigen::Matrix4d a = inv_sqrt_m.asDiagonal() * k * inv_sqrt_m.asDiagonal();
  const double fastest = std::sqrt(Eigen::SelfAdjointEigenSolver<Eigen::Matrix4d>(a).eigenvalues().maxCoeff());
  double got = 0.0;
  for (const auto& m : stability_limits(in).modes)
    if (m.contact == "pair d_min-d_max" && m.mode != "normal") got = std::max(got, m.omega);
  EXPECT_NEAR(got / fastest, 1.0, 1e-9);
}

TEST(CriticalStep, GershgorinBoundOfAGrainCagedBySixContacts) {
  // One mobile grain touching six fixed ones along the axes: its row of M^-1 K sums
  // 6 Kn / m translationally and 6 (Ks a^2 + b Ks r^2) / I rotationally, and the
  // bound is omega^2 = 2 (sum / m + sum / I). The fixed grains have no row.
  const double r = 0.5e-3, delta = 1e-6, kn = 3e7, ks = 2.7e7;
  Particles p;
  p.add(Vec3::Zero(), r, kDensity);
  for (int a = 0; a < 3; ++a)
    for (double sgn : {-1.0, 1.0}) p.add(sgn * (2.0 * r - delta) * Vec3::Unit(a), r, kDensity, true);
  const double m = mass_of(r), inertia = 0.4 * m * r * r, arm = r - 0.5 * delta;
  {
    World w(p, {}, open_domain(), law(kn, 0.0), options(safe_dt()));
    w.refresh();
    EXPECT_NEAR(stability_limits(w).omega_with_contacts, std::sqrt(2.0 * 6.0 * kn / m), 1e-9 * std::sqrt(kn / m));
  }
  World w(p, {}, open_domain(), law(kn, ks, 30.0, 1.0, 0.1), options(safe_dt()));
  w.refresh();
  const double w2 = 2.0 * (6.0 * kn / m + 6.0 * (ks * arm * arm + ks * r * r) / inertia);
  EXPECT_NEAR(stability_limits(w).omega_with_contacts / std::sqrt(w2), 1.0, 1e-9);
  // The bound is above every isolated contact's frequency.
  for (const auto& mode : stability_limits(w).modes) EXPECT_GT(std::sqrt(w2), mode.omega) << mode.mode;
}

TEST(CriticalStep, RefusesATooLargeStepNamingEachMode) {
  struct Case {
    ContactParams cp;
    std::string mode;
  };
  const Case cases[] = {{law(3e7, 0.0), "normal"},
                        {law(3e7, 2.7e7, 30.0, 1.0, 0.0), "tangential"},
                        {law(3e7, 2.7e7, 30.0, 40.0, 0.5), "rolling"}};
  for (const Case& c : cases) {
    Particles p;
    p.add(Vec3::Zero(), 0.5e-3, kDensity);
    p.add(Vec3(2e-3, 0, 0), 1e-3, kDensity);
    LimitInputs in;
    in.law = c.cp;
    in.m_min = mass_of(0.5e-3);
    in.r_min = 0.5e-3;
    in.m_max = mass_of(1e-3);
    in.r_max = 1e-3;
    const StabilityLimits lim = stability_limits(in);
    ASSERT_EQ(lim.governing().mode, c.mode);
    const double limit = lim.governing().dt_critical;
    EXPECT_NO_THROW(World(p, {}, open_domain(), c.cp, options(0.99 * limit)));
    try {
      World w(p, {}, open_domain(), c.cp, options(1.01 * limit));
      ADD_FAILURE() << "no refusal for mode " << c.mode;
    } catch (const TimestepError& e) {
      EXPECT_EQ(e.mode(), c.mode);
      EXPECT_NEAR(e.limit(), limit, 1e-12 * limit);
      EXPECT_NE(std::string(e.what()).find(c.mode), std::string::npos) << e.what();
    }
  }
}

// Grains inflated into overlap, started with 3x the critical step: the run must be
// stopped by the detector named, with every value still finite (stopped, not NaN).
World inflated_pack(double inflate, double dt_over_critical, double overlap_limit) {
  Vec3 hi;
  Particles p = cloud(300, 0.35, 5, 0.0, &hi);
  for (auto& r : p.r) r *= inflate;
  Domain dom;
  dom.hi = hi;
  const ContactParams cp = law(3e7, 2.7e7, 30.0, 1.0, 0.1);
  LimitInputs in;
  in.law = cp;
  in.m_min = in.m_max = mass_of(0.6e-3);
  in.r_min = in.r_max = 0.6e-3;
  WorldOptions o = options(dt_over_critical * stability_limits(in).governing().dt_critical);
  o.allow_unstable_dt = true;
  o.max_overlap_fraction = overlap_limit;
  return World(std::move(p), box_walls(Vec3::Zero(), hi), dom, cp, o);
}

void expect_stopped_by(double inflate, bool energy_guard, double overlap_limit, const std::string& quantity) {
  World w = inflated_pack(inflate, 3.0, overlap_limit);
  if (energy_guard) w.enable_energy_guard(0.05, 10);
  try {
    w.run(200000);
    FAIL() << "ran 200000 steps at 3x the critical step without being stopped";
  } catch (const InstabilityError& e) {
    EXPECT_EQ(e.quantity(), quantity) << e.what();
    EXPECT_GT(e.step(), 0);
    EXPECT_LT(e.step(), 5000) << "the detector should fire early, not after the blow-up is complete";
    EXPECT_GE(e.particle(), 0);
    EXPECT_NE(std::string(e.what()).find("step " + std::to_string(e.step())), std::string::npos) << e.what();
    const Particles& q = w.particles();
    for (std::size_t i = 0; i < q.size(); ++i)
      ASSERT_TRUE(std::isfinite(q.x[i].sum()) && std::isfinite(q.v[i].sum()) && std::isfinite(q.w[i].sum()))
          << "particle " << i << " went non-finite before the detector fired";
    std::printf("[ report   ] stopped: %s\n", e.what());
  }
}

TEST(Instability, OversizedStepOnAnOverlappingPackIsStoppedNotNaN) {
  // The energy guard alone (no overlap limit): energy grows where none can.
  expect_stopped_by(1.05, true, 1e9, "energy");
  // The overlap limit alone (no energy guard).
  expect_stopped_by(1.02, false, 0.25, "overlap");
  // The same pack at a stable step stays within the overlap limit: the step tripped it.
  World calm = inflated_pack(1.02, 0.3, 0.25);
  calm.enable_energy_guard(0.05, 10);
  EXPECT_NO_THROW(calm.run(2000));
}

TEST(Instability, StableRunWithTheGuardOnIsNotFlagged) {
  Vec3 hi;
  Particles p = cloud(300, 0.3, 5, 1.0, &hi);
  Domain dom;
  dom.hi = hi;
  World w(std::move(p), box_walls(Vec3::Zero(), hi), dom, law(3e7, 2.7e7, 30.0, 1.0, 0.1), options(safe_dt(0.2)));
  w.enable_energy_guard(0.01, 50);
  EXPECT_NO_THROW(w.run(5000));
}

namespace {

// A pack squeezed between six walls to about `pressure`, then held still and
// relaxed with local damping until it is static.
World static_pack(double pressure, double* wall_p) {
  Vec3 hi;
  Particles p = cloud(400, 0.36, 21, 0.0, &hi);
  p.scale_density(1e6);  // statics only: heavier grains allow a larger step
  Domain dom;
  dom.hi = hi;
  const double m_min = mass_of(0.5e-3) * 1e6;
  WorldOptions o = options(0.2 * std::sqrt(m_min / 3e7));
  o.local_damping = 0.7;
  World w(std::move(p), box_walls(Vec3::Zero(), hi), dom, law(3e7, 2.7e7, 20.0, 1.0, 0.1), o);
  auto mean_wall_pressure = [&]() {
    const auto& ws = w.walls();
    double s = 0;
    for (int a = 0; a < 3; ++a) {
      const int b = (a + 1) % 3, c = (a + 2) % 3;
      const double area = (ws[2 * b + 1].point[b] - ws[2 * b].point[b]) * (ws[2 * c + 1].point[c] - ws[2 * c].point[c]);
      s += (ws[2 * a].force.dot(-ws[2 * a].normal) + ws[2 * a + 1].force.dot(-ws[2 * a + 1].normal)) / (2 * area);
    }
    return s / 3;
  };
  // Each wall closes in with a proportional servo on its own force (step size set
  // by the stiffness of its contacts), then the pack relaxes with damping.
  auto area_of = [&](int a) {
    const auto& ws = w.walls();
    const int b = (a + 1) % 3, c = (a + 2) % 3;
    return (ws[2 * b + 1].point[b] - ws[2 * b].point[b]) * (ws[2 * c + 1].point[c] - ws[2 * c].point[c]);
  };
  // Impacts of heavy grains push back with about v sqrt(Kn m): keep that below the target.
  const double vmax = 1.0 * pressure * area_of(0) / std::sqrt(3e7 * mass_of(0.75e-3) * 1e6);
  for (int k = 0; k < 200000; ++k) {
    for (int s = 0; s < 6; ++s) {
      Wall& wall = w.walls()[s];
      const double f = wall.force.dot(-wall.normal), target = pressure * area_of(s / 2);
      // Close 30% of the force error per step, as if only the wall's contacts gave way.
      const double v = wall.contacts ? 0.3 * (target - f) / wall.stiffness / w.dt() : vmax;
      wall.velocity = std::clamp(v, -vmax, vmax) * wall.normal;
    }
    w.step();
    if (k % 100 == 0 && std::abs(mean_wall_pressure() / pressure - 1.0) < 0.005 && unbalanced_force_ratio(w) < 2e-3)
      break;
  }
  for (auto& wall : w.walls()) wall.velocity.setZero();
  *wall_p = mean_wall_pressure();
  std::printf("[ report   ] static pack: wall pressure %.4g Pa, unbalanced force ratio %.2e after %ld steps\n", *wall_p,
              unbalanced_force_ratio(w), w.step_count());
  return w;
}

}  // namespace

TEST(Stress, LoveWeberMatchesTheWallPressureOfAStaticPack) {
  double wall_p = 0;
  World w = static_pack(100e3, &wall_p);
  ASSERT_LT(unbalanced_force_ratio(w), 1e-2);
  ASSERT_GT(wall_p, 50e3);
  Vec3 lo, hi;
  for (int a = 0; a < 3; ++a) {
    lo[a] = w.walls()[2 * a].point[a];
    hi[a] = w.walls()[2 * a + 1].point[a];
  }
  const Mat3 s = love_weber_stress(w, Region{lo, hi});
  for (int a = 0; a < 3; ++a) {
    const double area = (hi - lo).prod() / (hi[a] - lo[a]);
    const double wall_s = 0.5 * (w.walls()[2 * a].force.dot(-w.walls()[2 * a].normal) +
                                 w.walls()[2 * a + 1].force.dot(-w.walls()[2 * a + 1].normal)) / area;
    EXPECT_NEAR(s(a, a) / wall_s, 1.0, 0.02) << "axis " << a << ": Love-Weber " << s(a, a) << " Pa, walls " << wall_s;
  }
  EXPECT_NEAR(s.trace() / 3.0 / wall_p, 1.0, 0.02);
}

TEST(Stress, RigidRotationOfThePackingLeavesTheStressInvariant) {
  double wall_p = 0;
  World w = static_pack(50e3, &wall_p);
  World turned = w;
  const Region big{Vec3::Constant(-1), Vec3::Constant(1)};
  const Vec3 centre = Vec3::Constant(0.01);
  const Mat3 q = Eigen::AngleAxisd(0.7, Vec3(1, 2, 3).normalized()).toRotationMatrix();
  turned.rotate(q, centre);
  const Mat3 s0 = love_weber_stress(w, big), s1 = love_weber_stress(turned, big);
  EXPECT_LT((s1 - q * s0 * q.transpose()).norm(), 1e-9 * s0.norm());
  // Invariants of the symmetric part (the antisymmetric part is the couple stress
  // the rolling moments carry).
  Eigen::SelfAdjointEigenSolver<Mat3> e0(0.5 * (s0 + s0.transpose())), e1(0.5 * (s1 + s1.transpose()));
  EXPECT_LT((e0.eigenvalues() - e1.eigenvalues()).norm(), 1e-9 * s0.norm());
  // The dynamics are frame-indifferent too: one more step in either frame agrees
  // (without Cundall's local damping, which acts per axis and so is not).
  w.set_local_damping(0.0);
  turned.set_local_damping(0.0);
  w.step();
  turned.step();
  const Mat3 s0b = love_weber_stress(w, big), s1b = love_weber_stress(turned, big);
  EXPECT_LT((s1b - q * s0b * q.transpose()).norm(), 1e-8 * s0b.norm());
}

TEST(Measurements, CoordinationAndEnergiesOfAKnownPair) {
  Particles p;
  p.add(Vec3::Zero(), 1e-3, kDensity);
  p.add(Vec3(1.999e-3, 0, 0), 1e-3, kDensity);
  p.add(Vec3(1.0, 0, 0), 1e-3, kDensity);  // a rattler far away
  p.v[2] = Vec3(1, 0, 0);
  World w(std::move(p), {}, open_domain(), law(3e7, 0.0), options(safe_dt()));
  w.refresh();
  const Coordination c = coordination(w);
  EXPECT_EQ(c.contacts, 1);
  EXPECT_NEAR(c.all, 2.0 / 3.0, 1e-12);
  EXPECT_EQ(c.rattlers, 3);  // each has fewer than two contacts
  const Energies e = energies(w);
  EXPECT_NEAR(e.translational, 0.5 * mass_of(1e-3), 1e-15);
  EXPECT_NEAR(e.normal, 0.5 * 3e7 * 1e-6 * 1e-6, 1e-15);
}

// Thornton's mechanical coordination, (2C - N1) / (N - N0 - N1): a triangle of three
// touching grains, a fourth hanging on one of them and a fifth touching nothing.
// Z = 3, 2, 2, 1, 0: all 8/5; without the rattlers and the pendant's contact, 7/3.
TEST(Measurements, MechanicalCoordinationDropsRattlersAndTheirContacts) {
  Particles p;
  const double d = 1.999e-3;
  p.add(Vec3(0, 0, 0), 1e-3, kDensity);
  p.add(Vec3(d, 0, 0), 1e-3, kDensity);
  p.add(Vec3(0.5 * d, d * std::sqrt(0.75), 0), 1e-3, kDensity);
  p.add(Vec3(-d, 0, 0), 1e-3, kDensity);   // hangs on grain 0 only
  p.add(Vec3(1.0, 0, 0), 1e-3, kDensity);  // touches nothing
  World w(std::move(p), {}, open_domain(), law(3e7, 0.0), options(safe_dt()));
  w.refresh();
  const Region all{Vec3::Constant(-1), Vec3::Constant(2)};
  for (const Coordination& c : {coordination(w), coordination(w, all)}) {
    EXPECT_EQ(c.contacts, 4);
    EXPECT_EQ(c.rattlers, 2);
    EXPECT_NEAR(c.all, 8.0 / 5.0, 1e-12);
    EXPECT_NEAR(c.mechanical, 7.0 / 3.0, 1e-12);
  }
}

// The solid inside a measurement volume (what the interior porosity is made of):
// spheres cut by its faces count their part inside, and Love-Weber's grains are
// those whose centres are in it. A 10 mm cube holding one whole sphere, one centred
// on its lower x face (half in), one 0.3 r inside its upper y face (a cap of height
// 0.7 r out) and one outside.
TEST(Measurements, SolidInARegionCutsTheSpheresItsFacesCross) {
  const double r = 1e-3;
  const Region box{Vec3::Zero(), Vec3::Constant(10e-3)};
  Particles p;
  p.add(Vec3(5e-3, 5e-3, 5e-3), r, kDensity);
  p.add(Vec3(0.0, 5e-3, 5e-3), r, kDensity);
  p.add(Vec3(5e-3, 10e-3 - 0.3 * r, 5e-3), r, kDensity);
  p.add(Vec3(20e-3, 5e-3, 5e-3), r, kDensity);
  const double v = 4.0 / 3.0 * M_PI * r * r * r;
  const double cap = M_PI * (0.7 * r) * (0.7 * r) * (3.0 * r - 0.7 * r) / 3.0;
  const RegionVolumes got = volumes_in(p, box);
  EXPECT_NEAR(got.solid, v + 0.5 * v + (v - cap), 1e-12 * v);
  EXPECT_NEAR(got.centres_inside, 3.0 * v, 1e-12 * v);
  EXPECT_GT(got.centres_inside, got.solid);  // the cut parts are counted whole by centre
}

// Love-Weber over a volume: each grain inside adds its own half of a contact, the
// branch from its centre to the contact point times the force. For one compressed
// pair of unequal radii along x, sigma_xx = arm * Kn * delta / V with the arm of the
// grain the volume holds, and the two halves add up to the centre distance.
TEST(Stress, LoveWeberTakesTheHalfOfAContactThatIsInside) {
  const double ri = 1e-3, rj = 0.5e-3, delta = 1e-6, kn = 3e7;
  Particles p;
  p.add(Vec3(0, 0, 0), ri, kDensity);
  p.add(Vec3(ri + rj - delta, 0, 0), rj, kDensity);
  World w(std::move(p), {}, open_domain(), law(kn, 0.0), options(safe_dt()));
  w.refresh();
  const Region only_i{Vec3(-2e-3, -1e-3, -1e-3), Vec3(0.5e-3, 1e-3, 1e-3)};
  const Region only_j{Vec3(0.5e-3, -1e-3, -1e-3), Vec3(3e-3, 1e-3, 1e-3)};
  const Region both{Vec3(-2e-3, -1e-3, -1e-3), Vec3(3e-3, 1e-3, 1e-3)};
  const double f = kn * delta;
  EXPECT_NEAR(love_weber_stress(w, only_i)(0, 0), (ri - 0.5 * delta) * f / only_i.volume(), 1e-9 * f / only_i.volume());
  EXPECT_NEAR(love_weber_stress(w, only_j)(0, 0), (rj - 0.5 * delta) * f / only_j.volume(), 1e-9 * f / only_j.volume());
  EXPECT_NEAR(love_weber_stress(w, both)(0, 0), (ri + rj - delta) * f / both.volume(), 1e-9 * f / both.volume());
  EXPECT_GT(love_weber_stress(w, both)(0, 0), 0.0);  // compression reads positive
}

// Over a region, a grain counts every contact it has, with grains outside the region
// and with walls: a chain floor - a - b - c with only a and b inside reads Z = 2 for
// both (a: floor and b; b: a and c), where the whole-box count gives a only one.
TEST(Measurements, CoordinationOverARegionCountsContactsWithWallsAndOutsiders) {
  Particles p;
  p.add(Vec3(0, 0, 0.999e-3), 1e-3, kDensity);    // a, on the floor
  p.add(Vec3(0, 0, 2.998e-3), 1e-3, kDensity);    // b, on a
  p.add(Vec3(0, 0, 4.997e-3), 1e-3, kDensity);    // c, on b, outside the region
  p.add(Vec3(0.5, 0, 2e-3), 1e-3, kDensity);      // d, inside, touching nothing
  std::vector<Wall> walls = {plane("floor", Vec3::Zero(), Vec3(0, 0, 1))};
  World w(std::move(p), std::move(walls), open_domain(), law(3e7, 0.0), options(safe_dt()));
  w.refresh();
  Region r;
  r.lo = Vec3(-1, -1, 0);
  r.hi = Vec3(1, 1, 4e-3);
  const Coordination in = coordination(w, r);
  EXPECT_EQ(in.contacts, 3);     // floor-a, a-b, b-c
  EXPECT_NEAR(in.all, 4.0 / 3.0, 1e-12);  // a 2, b 2, d 0
  EXPECT_EQ(in.rattlers, 1);     // d
  EXPECT_NEAR(in.mechanical, 2.0, 1e-12);
  const Coordination box = coordination(w);
  EXPECT_EQ(box.contacts, 2);    // pair contacts only
  EXPECT_NEAR(box.all, 1.0, 1e-12);  // a 1, b 2, c 1, d 0
}
