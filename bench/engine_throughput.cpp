// Engine throughput on a dense static pack: ns per particle-step and per contact,
// full contact law (friction and rolling resistance), 1 thread and all cores.
//
//   bench_engine_throughput [N ...] [--steps S] [--threads T ...]
//
// The pack: diameters uniform in [1, 2] mm, density scaled by 1e6 (statics),
// inserted at random, inflated to a solid fraction near 0.62 and relaxed with
// local damping between six walls until quiet; timing runs without damping.
#include "engine/measure.hpp"
#include "engine/packing.hpp"
#include "engine/timestep.hpp"
#include "engine/world.hpp"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>
#ifdef _OPENMP
#include <omp.h>
#endif

using namespace demcal::engine;

namespace {

std::vector<Wall> walls_of(const Vec3& hi) {
  std::vector<Wall> w;
  for (int a = 0; a < 3; ++a) {
    Wall lo, up;
    lo.name = "lo";
    lo.point = Vec3::Zero();
    lo.normal = Vec3::Unit(a);
    up.name = "hi";
    up.point = hi;
    up.normal = -Vec3::Unit(a);
    w.push_back(lo);
    w.push_back(up);
  }
  return w;
}

double wall_pressure(const World& w) {
  double s = 0;
  for (int a = 0; a < 3; ++a) {
    const double len = w.walls()[2 * a + 1].point[a] - w.walls()[2 * a].point[a];
    const double area = std::pow(len, 2);
    s += 0.5 * (w.walls()[2 * a].force.norm() + w.walls()[2 * a + 1].force.norm()) / area;
  }
  return s / 3;
}

World dense_pack(std::size_t n, int threads, bool rolling) {
  std::mt19937_64 rng(42);
  auto radii = sample_radii(n, 1e-3, 2e-3, rng);
  double vs = 0;
  for (double r : radii) vs += sphere_volume(r);
  const double phi0 = 0.30, phi1 = 0.62;
  const double edge = std::cbrt(vs / phi0);
  Particles p;
  insert_random(p, radii, Vec3::Zero(), Vec3::Constant(edge), 2650.0, rng);
  const double grow = std::cbrt(phi1 / phi0);
  for (std::size_t i = 0; i < p.size(); ++i) {
    p.r[i] *= grow;
    p.m[i] *= grow * grow * grow;
    p.inv_m[i] = 1.0 / p.m[i];
    p.inv_i[i] = 1.0 / (0.4 * p.m[i] * p.r[i] * p.r[i]);
  }
  // Walls at the centres' extent plus a radius: the inflated grains fill the box.
  p.scale_density(1e6);
  Domain dom;
  dom.hi = Vec3::Constant(edge);
  ContactParams law{3e7, 2.7e7, std::tan(30.0 * kPi / 180.0), 1.0, rolling ? 0.1 : 0.0};
  double m_min = 1e300;
  for (double m : p.m) m_min = std::min(m_min, m);
  WorldOptions o;
  o.dt = 0.15 * std::sqrt(m_min / law.kn);
  o.threads = threads;
  o.local_damping = 0.7;
  o.max_overlap_fraction = 1.0;
  World w(std::move(p), walls_of(Vec3::Constant(edge)), dom, law, o);
  for (int k = 0; k < 40 && (k < 4 || unbalanced_force_ratio(w) > 0.05); ++k) w.run(250);
  // Bisect a uniform scale of all radii between an unjammed and an over-compressed
  // state until the walls feel ~100 kPa, relaxing with damping at each trial: a
  // jammed pack at a realistic stress.
  const std::vector<double> r0 = w.particles().r;
  double s_lo = 0.9, s_hi = 1.0;
  for (int round = 0; round < 24; ++round) {
    const double s = 0.5 * (s_lo + s_hi);
    Particles& q = w.particles();
    for (std::size_t i = 0; i < q.size(); ++i) {
      q.r[i] = s * r0[i];
      q.v[i].setZero();  // Cundall damping does not slow free flight
      q.w[i].setZero();
    }
    w.invalidate_forces();
    w.run(1000);
    const double p_now = wall_pressure(w);
    (p_now > 100e3 ? s_hi : s_lo) = s;
    if (std::abs(p_now / 100e3 - 1.0) < 0.5 && unbalanced_force_ratio(w) < 0.05) break;
    if (s_hi - s_lo < 1e-4) break;
  }
  if (wall_pressure(w) < 10e3) {  // fell off the jamming point: go back to the jammed side
    Particles& q = w.particles();
    for (std::size_t i = 0; i < q.size(); ++i) {
      q.r[i] = s_hi * r0[i];
      q.v[i].setZero();
      q.w[i].setZero();
    }
    w.invalidate_forces();
    w.run(2000);
  }
  w.set_local_damping(0.0);
  return w;
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::size_t> sizes;
  std::vector<int> threads;
  long steps = 2000;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--steps" && i + 1 < argc) steps = std::atol(argv[++i]);
    else if (a == "--threads" && i + 1 < argc) threads.push_back(std::atoi(argv[++i]));
    else sizes.push_back(static_cast<std::size_t>(std::atol(a.c_str())));
  }
  if (sizes.empty()) sizes = {2000, 10000};
  if (threads.empty()) {
    threads.push_back(1);
#ifdef _OPENMP
    if (omp_get_num_procs() > 1) threads.push_back(omp_get_num_procs());
#endif
  }
  std::printf("%8s %7s %8s %9s %10s %12s %12s %9s\n", "N", "threads", "rolling", "contacts", "p [kPa]",
              "ns/part-step", "ns/contact", "speed-up");
  for (std::size_t n : sizes) {
    for (bool rolling : {true, false}) {
      double base = 0;
      for (int t : threads) {
        World w = dense_pack(n, t, rolling);
        const long contacts = coordination(w).contacts;
        w.run(50);  // warm the caches and the list
        const auto t0 = std::chrono::steady_clock::now();
        w.run(steps);
        const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
        const double ns_ps = s * 1e9 / (static_cast<double>(n) * steps);
        const double ns_c = s * 1e9 / (static_cast<double>(std::max(1L, contacts)) * steps);
        if (t == threads.front()) base = ns_ps;
        std::printf("%8zu %7d %8s %9.2f %10.1f %12.1f %12.1f %9.2f\n", n, t, rolling ? "yes" : "no",
                    2.0 * contacts / n, wall_pressure(w) / 1e3, ns_ps, ns_c, base / ns_ps);
        std::fflush(stdout);
      }
    }
  }
  return 0;
}
