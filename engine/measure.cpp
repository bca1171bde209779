#include "measure.hpp"

#include <algorithm>
#include <cmath>

namespace demcal::engine {

Energies energies(const World& world) {
  Energies e;
  const Particles& p = world.particles();
  const Vec3 g = world.options().gravity;
  for (std::size_t i = 0; i < p.size(); ++i) {
    if (p.fixed[i]) continue;
    e.translational += 0.5 * p.m[i] * p.v[i].squaredNorm();
    e.rotational += 0.5 * (0.4 * p.m[i] * p.r[i] * p.r[i]) * p.w[i].squaredNorm();
    e.gravity -= p.m[i] * g.dot(p.x[i]);
  }
  const ContactParams& law = world.law();
  world.for_each_contact([&](const ContactView& c) {
    e.normal += 0.5 * law.kn * c.delta * c.delta;
    if (law.ks > 0.0) e.tangential += 0.5 * c.fs.squaredNorm() / law.ks;
    const double kr = law.b * law.ks * c.r_roll * c.r_roll;
    if (kr > 0.0) e.rolling += 0.5 * c.mr.squaredNorm() / kr;
  });
  return e;
}

Mat3 love_weber_stress(const World& world, const Region& region) {
  const Particles& p = world.particles();
  Mat3 s = Mat3::Zero();
  world.for_each_contact([&](const ContactView& c) {
    // Each side of the contact contributes if its centre is inside the volume.
    if (region.contains(p.x[c.i])) s += (c.arm_i * c.n) * c.force.transpose();
    if (c.j >= 0 && region.contains(p.x[c.j])) s += (c.arm_j * c.n) * c.force.transpose();
  });
  // Branch on j points along -n and the force on j is -F: same sign as i's term.
  return -s / region.volume();
}

Coordination coordination(const World& world) {
  const Particles& p = world.particles();
  std::vector<int> z(p.size(), 0);
  long nc = 0;
  world.for_each_contact([&](const ContactView& c) {
    if (c.j < 0) return;
    ++nc;
    ++z[c.i];
    ++z[c.j];
  });
  long np = 0, n0 = 0, n1 = 0, zsum = 0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    if (p.fixed[i]) continue;
    ++np;
    zsum += z[i];
    n0 += z[i] == 0;
    n1 += z[i] == 1;
  }
  Coordination out;
  out.contacts = nc;
  out.rattlers = n0 + n1;
  if (np > 0) out.all = static_cast<double>(zsum) / static_cast<double>(np);
  if (np - n0 - n1 > 0) out.mechanical = static_cast<double>(zsum - n1) / static_cast<double>(np - n0 - n1);
  return out;
}

Coordination coordination(const World& world, const Region& region) {
  const Particles& p = world.particles();
  std::vector<int> z(p.size(), 0);
  std::vector<char> inside(p.size(), 0);
  for (std::size_t i = 0; i < p.size(); ++i) inside[i] = !p.fixed[i] && region.contains(p.x[i]);
  long nc = 0;
  world.for_each_contact([&](const ContactView& c) {
    const bool in_i = inside[c.i], in_j = c.j >= 0 && inside[c.j];
    if (!in_i && !in_j) return;
    ++nc;
    ++z[c.i];
    if (c.j >= 0) ++z[c.j];
  });
  long np = 0, n0 = 0, n1 = 0, zsum = 0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    if (!inside[i]) continue;
    ++np;
    zsum += z[i];
    n0 += z[i] == 0;
    n1 += z[i] == 1;
  }
  Coordination out;
  out.contacts = nc;
  out.rattlers = n0 + n1;
  if (np > 0) out.all = static_cast<double>(zsum) / static_cast<double>(np);
  if (np - n0 - n1 > 0) out.mechanical = static_cast<double>(zsum - n1) / static_cast<double>(np - n0 - n1);
  return out;
}

double unbalanced_force_ratio(const World& world) {
  const Particles& p = world.particles();
  long nm = 0;
  for (std::size_t i = 0; i < p.size(); ++i) nm += !p.fixed[i];
  const double fsum = world.net_force_sum();
  double csum = 0.0;
  long nc = 0;
  world.for_each_contact([&](const ContactView& c) {
    csum += c.force.norm();
    ++nc;
  });
  if (nm == 0) return 0.0;
  if (nc == 0 || csum == 0.0) return fsum > 0.0 ? INFINITY : 0.0;
  return (fsum / nm) / (csum / nc);
}

double solid_volume(const World& world) {
  const Particles& p = world.particles();
  double v = 0.0;
  for (std::size_t i = 0; i < p.size(); ++i)
    if (!p.fixed[i]) v += sphere_volume(p.r[i]);
  return v;
}

namespace {

// Volume of the part of a sphere of radius r on the far side of a plane at
// distance h from its centre (h >= r: none, h <= -r: all).
double cap_volume(double r, double h) {
  if (h >= r) return 0.0;
  if (h <= -r) return sphere_volume(r);
  const double t = r - h;  // cap height
  return kPi * t * t * (3.0 * r - t) / 3.0;
}

}  // namespace

RegionVolumes volumes_in(const Particles& p, const Region& reg) {
  RegionVolumes out;
  for (std::size_t i = 0; i < p.size(); ++i) {
    const double r = p.r[i];
    const Vec3& x = p.x[i];
    if (reg.contains(x)) out.centres_inside += sphere_volume(r);
    double v = sphere_volume(r);
    for (int a = 0; a < 3; ++a) {
      v -= cap_volume(r, x[a] - reg.lo[a]);  // part below lo
      v -= cap_volume(r, reg.hi[a] - x[a]);  // part above hi
    }
    out.solid += std::max(0.0, v);
  }
  return out;
}

}  // namespace demcal::engine
