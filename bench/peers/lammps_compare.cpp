// The demcal half of bench/peers/run_lammps_compare.sh: loads the dense pack that
// bench_engine_throughput caches (BENCH_PACK_DIR), writes the same grains and walls
// as a LAMMPS data file and input script, then times demcal on it: 200 untimed
// steps (contact springs build up), then S timed steps on one thread.
//
//   bench_lammps_compare PACK.bin --steps S --lammps-dir DIR
#include "engine/measure.hpp"
#include "engine/world.hpp"
#include "../pack_file.hpp"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

using namespace demcal::engine;
using demcal::bench::load_pack;

int main(int argc, char** argv) {
  std::string pack, dir = ".";
  long steps = 2000;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--steps" && i + 1 < argc) steps = std::atol(argv[++i]);
    else if (a == "--lammps-dir" && i + 1 < argc) dir = argv[++i];
    else pack = a;
  }
  Particles p;
  std::vector<Wall> walls;
  if (pack.empty() || !load_pack(pack, p, walls)) {
    std::fprintf(stderr, "usage: bench_lammps_compare PACK.bin [--steps S] [--lammps-dir DIR] (cannot read \"%s\")\n",
                 pack.c_str());
    return 2;
  }
  const double kn = 3e7, ks = 2.7e7, theta = 30.0 * kPi / 180.0, b = 1.0, eta = 0.1;
  double m_min = 1e300, d_min = 1e300;
  for (std::size_t i = 0; i < p.size(); ++i) {
    m_min = std::min(m_min, p.m[i]);
    d_min = std::min(d_min, 2.0 * p.r[i]);
  }
  const double dt = 0.15 * std::sqrt(m_min / kn);
  const double skin = 0.1 * d_min;  // demcal's default skin
  const Vec3 lo(walls[0].point.x(), walls[2].point.y(), walls[4].point.z());
  const Vec3 hi(walls[1].point.x(), walls[3].point.y(), walls[5].point.z());

  // LAMMPS data file (atom_style sphere: id type diameter density x y z).
  {
    std::FILE* f = std::fopen((dir + "/pack.data").c_str(), "w");
    const Vec3 m = 0.02 * (hi - lo);  // box a little larger than the walls
    std::fprintf(f, "demcal dense pack\n\n%zu atoms\n1 atom types\n\n", p.size());
    std::fprintf(f, "%.17g %.17g xlo xhi\n%.17g %.17g ylo yhi\n%.17g %.17g zlo zhi\n\nAtoms # sphere\n\n",
                 lo.x() - m.x(), hi.x() + m.x(), lo.y() - m.y(), hi.y() + m.y(), lo.z() - m.z(), hi.z() + m.z());
    for (std::size_t i = 0; i < p.size(); ++i) {
      const double d = 2.0 * p.r[i];
      const double rho = p.m[i] / (kPi / 6.0 * d * d * d);
      std::fprintf(f, "%zu 1 %.17g %.17g %.17g %.17g %.17g\n", i + 1, d, rho, p.x[i].x(), p.x[i].y(), p.x[i].z());
    }
    std::fclose(f);
  }
  // LAMMPS input: pair granular with the same law as far as LAMMPS can say it
  // (docs/performance.md, "Against LAMMPS", for the mapping and what differs).
  {
    std::FILE* f = std::fopen((dir + "/in.compare").c_str(), "w");
    std::fprintf(f,
                 "units si\natom_style sphere\natom_modify map array\nboundary f f f\ncomm_modify vel yes\n"
                 "newton off\nread_data %s/pack.data\n"
                 "pair_style granular\n"
                 "pair_coeff * * hooke %.17g 0.0 tangential linear_history %.17g 0.0 %.17g "
                 "rolling sds %.17g 0.0 %.17g\n"
                 "neighbor %.17g bin\nneigh_modify delay 0 every 1 check yes\n"
                 "fix integrate all nve/sphere\n"
                 "fix wx all wall/gran hooke %.17g NULL 0.0 NULL 0.0 0 xplane %.17g %.17g\n"
                 "fix wy all wall/gran hooke %.17g NULL 0.0 NULL 0.0 0 yplane %.17g %.17g\n"
                 "fix wz all wall/gran hooke %.17g NULL 0.0 NULL 0.0 0 zplane %.17g %.17g\n"
                 "timestep %.17g\nthermo_style custom step ke\nthermo %ld\n"
                 "run 200\nrun %ld\n",
                 dir.c_str(), kn, ks, std::tan(theta), 4.0 * b * ks, 2.0 * eta, skin, kn, lo.x(), hi.x(), kn,
                 lo.y(), hi.y(), kn, lo.z(), hi.z(), dt, steps, steps);
    std::fclose(f);
  }

  Domain dom;
  dom.lo = lo;
  dom.hi = hi;
  WorldOptions o;
  o.dt = dt;
  o.threads = 1;
  o.skin = skin;
  World w(std::move(p), walls, dom, ContactParams{kn, ks, std::tan(theta), b, eta}, o);
  w.run(200);
  const long contacts = coordination(w).contacts;
  const auto t0 = std::chrono::steady_clock::now();
  w.run(steps);
  const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("demcal: %zu grains, %ld pair contacts, %ld steps, dt %.4g s, %.6g s -> %.2f ns/particle-step\n",
              w.particles().size(), contacts, steps, dt, secs, secs * 1e9 / (double(w.particles().size()) * steps));
  return 0;
}
