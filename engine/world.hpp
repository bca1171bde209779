#pragma once
// The DEM system: particles, walls, contact law, neighbour list and the velocity
// Verlet integrator. Scenes drive a World; measurements read it.
#include "contact_law.hpp"
#include "domain.hpp"
#include "material.hpp"
#include "neighbor_grid.hpp"
#include "particles.hpp"
#include "wall.hpp"

#include <atomic>
#include <chrono>
#include <string>
#include <vector>

namespace demcal::engine {

struct WorldOptions {
  double dt = 0.0;              // time step [s]; must be set
  double skin = 0.0;            // Verlet skin [m]; 0 picks 0.1 * smallest diameter
  Vec3 gravity = Vec3::Zero();  // [m/s^2]
  double local_damping = 0.0;   // Cundall's non-viscous damping, preparation only
  double max_overlap_fraction = 0.25;  // overlap / smaller radius that counts as blown up
  int threads = 1;
  bool allow_unstable_dt = false;  // for stability studies only: skip the critical-step refusal
};

// Per-thread accumulators of the force evaluation, padded against false sharing.
struct alignas(64) ThreadAcc {
  double max_overlap = 0.0;  // largest overlap / radius seen by the thread
  long max_overlap_i = -1;
  bool finite = true;        // the thread's grains ended the step with finite x, v, w
  double net_force_sum = 0.0;  // sum of |F| over the thread's free grains before local damping
  // A grain of the thread's block used up half the Verlet skin. Every thread reads all
  // the flags after the barrier that follows the drift while others already write
  // the fields above: assign fields one by one inside a parallel region, never the
  // whole struct.
  bool stale = false;
};
// Where a thread's pair loop puts forces and torques: grains below `bound` (its own
// block) in the grains' arrays, grains at or above it in the thread's buffers.
struct ForceSink {
  Vec3* f;
  Vec3* t;
  Vec3* buf_f;
  Vec3* buf_t;
  int bound;
};

// The number of the last force evaluation whose pair rows a block has finished,
// published with release order after its buffer is written, read with acquire order
// by the blocks above before they add that buffer. A copied world copies the value.
struct alignas(64) BlockMark {
  std::atomic<long> done{-1};
  BlockMark() = default;
  BlockMark(const BlockMark& o) : done(o.done.load(std::memory_order_relaxed)) {}
  BlockMark& operator=(const BlockMark& o) {
    done.store(o.done.load(std::memory_order_relaxed), std::memory_order_relaxed);
    return *this;
  }
};

// One thread's sum over its grains of the force on them from one wall.
struct alignas(64) WallPartial {
  Vec3 force = Vec3::Zero();
  int contacts = 0;
};

// Wall-clock seconds spent in each phase of the step since the world was made:
// what a profile of a run costs nothing to read.
struct PhaseTimes {
  double neighbor = 0.0;   // list rebuilds, wall candidate lists (the skin test is in the drift pass)
  double pairs = 0.0;      // grain-grain contact law, force reduction across threads
  double walls = 0.0;      // grain-wall contacts
  double integrate = 0.0;  // velocity Verlet passes with the skin test, gravity, damping, checks
};

// One contact as measurements see it (recomputed from positions and history).
struct ContactView {
  int i;
  int j;                 // other particle, or -1 for a wall
  int wall;              // wall index, or -1 for a pair
  Vec3 n;                // unit normal from i towards j / the wall
  double delta;          // overlap
  Vec3 force;            // force on i
  Vec3 fs, mr;           // tangential force and rolling moment on i
  double arm_i, arm_j;   // distance from each centre to the contact point
  double r_roll;
};

class World {
 public:
  World(Particles particles, std::vector<Wall> walls, const Domain& domain, const ContactParams& law,
        const WorldOptions& options);

  // One velocity-Verlet step of translation and rotation.
  void step();
  void run(long steps) {
    for (long s = 0; s < steps; ++s) step();
  }

  // Stage switches (dense preparation sets friction after a frictionless stage).
  void set_contact_params(const ContactParams& law);
  void set_local_damping(double alpha) { opt_.local_damping = alpha; }
  void set_dt(double dt);
  void invalidate_forces() { forces_valid_ = false; }
  // Evaluates forces (and contact flags) for the current state if they are stale;
  // measurements read contacts, so call this before measuring a fresh world.
  void refresh() {
    if (!forces_valid_) compute_forces();
  }

  // Rotates the whole system rigidly about `centre`: grains, walls and every
  // contact's history. Used to check frame indifference.
  void rotate(const Mat3& q, const Vec3& centre);

  // Energy-balance guard: from now on, total energy (kinetic + elastic + gravity)
  // may not exceed its present value plus the work done by moving walls by more
  // than `rel_tolerance` of the reference; checked every `interval` steps.
  void enable_energy_guard(double rel_tolerance, long interval = 100);
  void disable_energy_guard() { guard_tol_ = -1.0; }

  const Particles& particles() const { return p_; }
  Particles& particles() { return p_; }
  const std::vector<Wall>& walls() const { return walls_; }
  std::vector<Wall>& walls() { return walls_; }
  const Domain& domain() const { return dom_; }
  Domain& domain() { return dom_; }
  const ContactParams& law() const { return law_; }
  const WorldOptions& options() const { return opt_; }
  const NeighborList& neighbors() const { return nl_; }

  long step_count() const { return step_; }
  double time() const { return time_; }
  double dt() const { return opt_.dt; }
  double skin() const { return skin_; }
  double wall_work() const { return wall_work_; }  // work done on the grains by moving walls [J]
  double max_overlap_ratio() const { return max_overlap_ratio_; }  // of the last force evaluation
  // Sum over free grains of |net force| (contacts and gravity) of the last force
  // evaluation, taken before local damping: damping scales each component by
  // 1 -+ alpha, which is not an imbalance of the grain. Measurements of equilibrium
  // read this (as YADE's and PFC's unbalanced force do), not the damped force.
  double net_force_sum() const;
  const PhaseTimes& phase_times() const { return times_; }

  // Calls f(const ContactView&) for every live contact, pairs then walls. Serial.
  template <class F>
  void for_each_contact(F&& f) const;

  // Total energy the guard watches: kinetic + elastic + gravitational potential.
  double guard_energy() const;

 private:
  void compute_forces();
  // Forces for the current positions (the neighbour list rebuilt first when
  // `rebuild`); with `kick`, each thread then ends the step of its own grains (the
  // second half-kick) in the same parallel region. Returns whether all grains are finite.
  bool evaluate_forces(bool rebuild, bool kick);
  void begin_forces(bool rebuild, std::chrono::steady_clock::time_point& clock);
  void clear_thread_sums();
  void block_forces(bool kick, std::chrono::steady_clock::time_point& clock, double& t_pairs, double& t_walls);
  bool end_forces(std::chrono::steady_clock::time_point& clock, double t_pairs, double t_walls);
  void half_kick(int begin, int end, int shared_end, ThreadAcc& acc);
  template <bool Periodic>
  bool drift_block(int blk, bool listed);
  template <bool Periodic>
  bool drift(bool listed);
  template <bool Periodic>
  bool drift_and_forces(bool& finite);
  template <bool Periodic, bool Friction>
  void force_range(int begin, int end, const ForceSink& out, ThreadAcc& acc);
  void assign_blocks();
  void block_pairs(int blk, bool periodic, bool frictional);
  void add_lower_buffers(int blk);
  void wait_for_lower_blocks(int blk, long eval) const;
  void finish_grains(int blk, int begin, int end, bool kick, int tid,
                     std::chrono::steady_clock::time_point& clock, double& t_walls);
  int shared_hi(int blk) const;
  bool blocks_fit() const;
  bool blocks_stale() const;
  int block_lo(int tid) const;
  bool wall_candidates_stale() const;
  void update_wall_candidates();
  void wall_forces(int begin, int end, ThreadAcc& acc, WallPartial* part);
  // A grain-wall contact that is open (or cannot be closed) keeps no history.
  void open_wall_contact(std::size_t slot) {
    if (!wall_touch_[slot]) return;
    wall_fs_[slot].setZero();
    wall_mr_[slot].setZero();
    wall_touch_[slot] = 0;
  }
  void smooth_wall_forces(std::size_t w, const int* first, const int* last, ThreadAcc& acc, WallPartial& sum);
  void external_forces(int begin, int end, ThreadAcc& acc);
  double free_force_sum(int begin, int end) const;
  void check_finite_and_overlap();
  void check_energy();

  Particles p_;
  std::vector<Wall> walls_;
  Domain dom_;
  ContactParams law_;
  WorldOptions opt_;
  NeighborList nl_;
  double skin_ = 0.0;

  // Per-wall contact history, indexed [wall * N + particle].
  std::vector<Vec3> wall_fs_, wall_mr_;
  std::vector<std::uint8_t> wall_touch_;
  // Grains within a skin of each wall, rebuilt with the neighbour list or when a
  // wall has moved more than half the skin.
  std::vector<std::vector<int>> wall_near_;
  std::vector<Vec3> wall_point_build_;
  long wall_list_builds_ = -1;

  // Thread-private buffers for the forces a block's pairs put on grains above the
  // block, the threads' overlap maxima and their sums of each wall's force
  // ([thread * walls + wall]).
  std::vector<std::vector<Vec3>> buf_f_, buf_t_;
  std::vector<int> row_lo_;  // first pair row of each thread's block, and n
  std::vector<int> reach_;   // one past the highest grain each block's list entries name
  // One past the highest grain of each block that a lower block's pairs reach: the
  // block's grains [row_lo_, shared_hi_) are read by another thread's pair loop.
  std::vector<int> shared_hi_;
  std::vector<BlockMark> marks_;  // per block: the last evaluation whose pairs it finished
  long evals_ = 0;                // force evaluations so far (the marks' numbers)
  long blocks_builds_ = -1;  // the list build the blocks were cut for
  std::vector<ThreadAcc> acc_;
  std::vector<WallPartial> wall_part_;

  long step_ = 0;
  double time_ = 0.0;
  bool forces_valid_ = false;
  double wall_work_ = 0.0;
  double max_overlap_ratio_ = 0.0;
  long max_overlap_particle_ = -1;
  bool damped_ = false;           // local damping acted in the last force evaluation
  double net_force_sum_ = 0.0;    // its sum of |F| before damping (when damped_)

  PhaseTimes times_;

  double guard_tol_ = -1.0;
  long guard_interval_ = 100;
  double guard_ref_ = 0.0;
  double guard_work_ref_ = 0.0;
};

template <class F>
void World::for_each_contact(F&& f) const {
  const int n = static_cast<int>(p_.size());
  const bool listed = nl_.start.size() == p_.size() + 1;  // no list before the first force evaluation
  for (int i = 0; listed && i < n; ++i) {
    for (int e = nl_.start[i]; e < nl_.start[i + 1]; ++e) {
      if (!nl_.touching[e]) continue;
      const int j = nl_.j[e];
      Vec3 d = p_.x[j] - p_.x[i];
      dom_.min_image(d);
      const double dist = d.norm();
      const double delta = p_.r[i] + p_.r[j] - dist;
      if (delta <= 0.0) continue;
      ContactView c;
      c.i = i;
      c.j = j;
      c.wall = -1;
      c.n = d / dist;
      c.delta = delta;
      c.fs = nl_.fs[e];
      c.mr = nl_.mr[e];
      c.force = c.fs - law_.kn * delta * c.n;
      c.arm_i = p_.r[i] - 0.5 * delta;
      c.arm_j = p_.r[j] - 0.5 * delta;
      c.r_roll = 0.5 * (p_.r[i] + p_.r[j]);
      f(c);
    }
  }
  for (std::size_t w = 0; w < walls_.size() && wall_fs_.size() == walls_.size() * p_.size(); ++w) {
    const Wall& wall = walls_[w];
    if (!wall.active) continue;
    for (int i = 0; i < n; ++i) {
      // Walls exert nothing on fixed grains (update_wall_candidates): a floor grain
      // beyond a wall's plane is no contact, whatever its overlap with the plane.
      if (p_.fixed[i]) continue;
      const double h = wall.distance(p_.x[i]);
      const double delta = p_.r[i] - h;
      if (delta <= 0.0) continue;
      const std::size_t k = w * p_.size() + static_cast<std::size_t>(i);
      ContactView c;
      c.i = i;
      c.j = -1;
      c.wall = static_cast<int>(w);
      c.n = -wall.normal;
      c.delta = delta;
      c.fs = wall_fs_[k];
      c.mr = wall_mr_[k];
      c.force = c.fs - law_.kn * delta * c.n;
      c.arm_i = h;
      c.arm_j = 0.0;
      c.r_roll = p_.r[i];
      f(c);
    }
  }
}

}  // namespace demcal::engine
