#pragma once
// Macroscopic measurements of a World (seed Eqs. 2.7, 2.8, 2.12, 2.13).
#include "types.hpp"
#include "world.hpp"

namespace demcal::engine {

struct Energies {
  double translational = 0, rotational = 0;
  double normal = 0, tangential = 0, rolling = 0;  // elastic energy in the springs
  double gravity = 0;                               // -sum m g.x (relative to the origin)
  double kinetic() const { return translational + rotational; }
  double elastic() const { return normal + tangential + rolling; }
  double total() const { return kinetic() + elastic() + gravity; }
};
Energies energies(const World& world);

// Axis-aligned measurement volume.
struct Region {
  Vec3 lo, hi;
  double volume() const { return (hi - lo).prod(); }
  bool contains(const Vec3& x) const {
    return (x.array() >= lo.array()).all() && (x.array() < hi.array()).all();
  }
};

// Love-Weber stress over the particles whose centres lie in `region` (seed Eq. 2.7):
// sigma = -(1/V) sum_p sum_c (x_c - x_p) (x) F_c, compression positive. Since
// (1 - n) / sum V_p = 1 / V, the seed's porosity-weighted form is the same thing.
Mat3 love_weber_stress(const World& world, const Region& region);

struct Coordination {
  double all = 0;         // 2 Nc / Np over mobile grains, pair contacts only
  double mechanical = 0;  // without rattlers (< 2 contacts): (2Nc - N1) / (Np - N0 - N1)
  long contacts = 0;
  long rattlers = 0;
};
Coordination coordination(const World& world);
// The same over the grains whose centres lie in `region` (seed Eq. 2.8 over the
// Love-Weber volume): every contact of such a grain counts, with grains outside the
// region and with walls. Over the whole box, grains at the walls lose the contacts
// the walls give them and read as rattlers; on a 1,000-grain sample that is 4.52
// against 5.27 in the interior after preparation.
Coordination coordination(const World& world, const Region& region);

// Mean |net force| over mobile grains / mean |contact force|: 0 in static equilibrium.
// The net force is taken before local damping (World::net_force_sum).
double unbalanced_force_ratio(const World& world);

// Sum of the volumes of mobile grains.
double solid_volume(const World& world);

// Grain volume in a region, two ways: the solid actually inside it (each sphere cut
// by the region's faces; one cut by two faces at once, near an edge, is
// approximated by subtracting both caps), and the whole volume of the grains whose
// centres lie inside (what Love-Weber's sum counts).
struct RegionVolumes {
  double solid = 0.0;
  double centres_inside = 0.0;
};
RegionVolumes volumes_in(const Particles& p, const Region& region);

}  // namespace demcal::engine
