#include "world.hpp"

#include "contact_batch.hpp"
#include "errors.hpp"
#include "timestep.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <sstream>
#include <thread>
#ifdef _OPENMP
#include <omp.h>
#endif

namespace demcal::engine {

namespace {

int thread_id() {
#ifdef _OPENMP
  return omp_get_thread_num();
#else
  return 0;
#endif
}

int team_size() {
#ifdef _OPENMP
  return omp_get_num_threads();
#else
  return 1;
#endif
}

// The pair loop and the damping read arrays of Vec3 as flat arrays of doubles.
static_assert(sizeof(Vec3) == 3 * sizeof(double), "Vec3 arrays are read as flat doubles");

// A lower block's pair loop has read the lines of grains [row_lo_, shared_hi_) of
// a block, so they sit shared in that core's cache too, and a write to one waits
// until the other copy is invalidated. Asking for the lines ahead for writing
// overlaps those waits (2,000 grains, two threads: the drift of the upper block
// 6.0 -> 4.3 us a step, its kick 6.5 -> 3.8; performance.md). Only those grains:
// on one thread, or for the rest of a block, the prefetch costs and buys nothing.
constexpr int kPrefetchAhead = 16;  // grains: 6 lines of each array ahead
inline void prefetch_for_write(const Vec3* p) { __builtin_prefetch(p, 1, 3); }

double seconds_since(std::chrono::steady_clock::time_point& t) {
  const auto now = std::chrono::steady_clock::now();
  const double s = std::chrono::duration<double>(now - t).count();
  t = now;
  return s;
}

void require_finite_positive(double v, const char* field) {
  if (!std::isfinite(v) || v <= 0.0) throw ConfigError(field, "must be a finite positive number");
}

}  // namespace

World::World(Particles particles, std::vector<Wall> walls, const Domain& domain, const ContactParams& law,
             const WorldOptions& options)
    : p_(std::move(particles)), walls_(std::move(walls)), dom_(domain), law_(law), opt_(options) {
  require_finite_positive(opt_.dt, "dt");
  require_finite_positive(law_.kn, "material.kn");
  if (!std::isfinite(law_.ks) || law_.ks < 0.0) throw ConfigError("material.ks", "must be finite and >= 0");
  if (!std::isfinite(opt_.local_damping) || opt_.local_damping < 0.0 || opt_.local_damping >= 1.0)
    throw ConfigError("local_damping", "must lie in [0, 1)");
  if (opt_.threads < 1) opt_.threads = 1;
  for (auto& w : walls_) {
    const double len = w.normal.norm();
    if (!(len > 0.0) || !std::isfinite(len)) throw ConfigError("wall." + w.name + ".normal", "must be a non-zero vector");
    w.normal /= len;
  }
  double d_min = 1e300;
  for (std::size_t i = 0; i < p_.size(); ++i) d_min = std::min(d_min, 2.0 * p_.r[i]);
  skin_ = opt_.skin > 0.0 ? opt_.skin : (p_.size() ? 0.1 * d_min : 0.0);
  const std::size_t nw = walls_.size() * p_.size();
  wall_fs_.assign(nw, Vec3::Zero());
  wall_mr_.assign(nw, Vec3::Zero());
  wall_touch_.assign(nw, 0);
  if (!opt_.allow_unstable_dt) check_timestep(opt_.dt, stability_limits(*this));
  buf_f_.resize(opt_.threads);  // sized when the first blocks are cut
  buf_t_.resize(opt_.threads);
}

void World::set_contact_params(const ContactParams& law) {
  law_ = law;
  // A frictionless law neither reads nor writes the springs' history (the pair loop
  // skips it): clear it here so that none is left to reappear when friction returns.
  if (law_.ks <= 0.0) {
    std::fill(nl_.fs.begin(), nl_.fs.end(), Vec3::Zero());
    std::fill(nl_.mr.begin(), nl_.mr.end(), Vec3::Zero());
    std::fill(wall_fs_.begin(), wall_fs_.end(), Vec3::Zero());
    std::fill(wall_mr_.begin(), wall_mr_.end(), Vec3::Zero());
  }
  if (!opt_.allow_unstable_dt) check_timestep(opt_.dt, stability_limits(*this));
  forces_valid_ = false;
}

void World::set_dt(double dt) {
  require_finite_positive(dt, "dt");
  if (!opt_.allow_unstable_dt) check_timestep(dt, stability_limits(*this, dt));
  opt_.dt = dt;
}

void World::rotate(const Mat3& q, const Vec3& centre) {
  for (std::size_t i = 0; i < p_.size(); ++i) {
    p_.x[i] = centre + q * (p_.x[i] - centre);
    p_.v[i] = q * p_.v[i];
    p_.w[i] = q * p_.w[i];
    p_.f[i] = q * p_.f[i];
    p_.t[i] = q * p_.t[i];
  }
  for (auto& w : walls_) {
    w.point = centre + q * (w.point - centre);
    w.normal = q * w.normal;
    w.velocity = q * w.velocity;
    w.force = q * w.force;
  }
  for (auto& h : nl_.fs) h = q * h;
  for (auto& h : nl_.mr) h = q * h;
  for (auto& h : wall_fs_) h = q * h;
  for (auto& h : wall_mr_) h = q * h;
  wall_list_builds_ = -1;  // walls turned: their candidate lists are stale
  // Same pairs, history carried over; forces were rotated, so they stay valid.
  if (nl_.start.size() == p_.size() + 1) nl_.build(p_, dom_, skin_, opt_.threads);
}

namespace {

// The arrays the Verlet passes touch, as plain pointers held in a local: reached
// through `this`, their addresses were reloaded for every grain (stores of doubles
// might alias them).
struct VerletArrays {
  Vec3 *x, *v, *w;
  const Vec3 *f, *t;
  const double *inv_m, *inv_i;
  explicit VerletArrays(Particles& p)
      : x(p.x.data()), v(p.v.data()), w(p.w.data()), f(p.f.data()), t(p.t.data()),
        inv_m(p.inv_m.data()), inv_i(p.inv_i.data()) {}
  // Half a step of velocity Verlet's kick for grain i. Fixed grains have 1/m = 1/I = 0
  // (Particles::add), so they keep their velocity without a branch per grain.
  void kick(int i, double half) const {
    v[i] += (half * inv_m[i]) * f[i];
    w[i] += (half * inv_i[i]) * t[i];
  }
};

// The components of an array of Vec3 as one flat array of doubles (x0 y0 z0 x1 ...),
// for a loop that moves them one by one. Null for an empty array: its data() may be
// null, and ->data() through a null pointer is undefined.
double* flat(std::vector<Vec3>& v) { return v.empty() ? nullptr : v.data()->data(); }

// Scatters a finished batch: forces and torques onto the grains, history back into
// the list, the largest overlap into the thread's accumulator. A frictionless batch
// has forces along the normal only: no torques, no history.
template <bool Friction>
void scatter_batch(const PairBatch& b, const ForceSink& out, Vec3* FS, Vec3* MR, ThreadAcc& acc) {
  Vec3* F = out.f;
  Vec3* T = out.t;
  // Lanes come row by row: sum each row's force and torque on i in registers and
  // store once, instead of a load-add-store chain through the same address.
  int row = b.count > 0 ? b.i[0] : 0;
  Vec3 fi = Vec3::Zero(), ti = Vec3::Zero();
  for (int l = 0; l < b.count; ++l) {
    const int i = b.i[l], j = b.j[l], e = b.e[l];
    if (i != row) {
      F[row] += fi;
      if constexpr (Friction) T[row] += ti;
      fi.setZero();
      ti.setZero();
      row = i;
    }
    const Vec3 f(b.fx[l], b.fy[l], b.fz[l]);
    fi += f;
    // Grains above the block go to the thread's buffer: a select, not a branch.
    const bool mine = j < out.bound;
    (mine ? F : out.buf_f)[j] -= f;
    if constexpr (Friction) {
      ti += Vec3(b.tix[l], b.tiy[l], b.tiz[l]);
      (mine ? T : out.buf_t)[j] += Vec3(b.tjx[l], b.tjy[l], b.tjz[l]);
      FS[e] = Vec3(b.fsx[l], b.fsy[l], b.fsz[l]);
      MR[e] = Vec3(b.mrx[l], b.mry[l], b.mrz[l]);
    }
    const double rmin = std::min(b.ri[l], b.rj[l]);
    if (b.delta[l] > acc.max_overlap * rmin) {  // divide only for a new maximum
      acc.max_overlap = b.delta[l] / rmin;
      acc.max_overlap_i = i;
    }
  }
  if (b.count > 0) {
    F[row] += fi;
    if constexpr (Friction) T[row] += ti;
  }
}

}  // namespace

// Pair contacts of rows [begin, end): touching pairs are packed lane by lane into a
// batch, the law runs over the batch (contact_batch.hpp), results are scattered.
// Frictionless (dense preparation's first stage, the collision test): the law needs
// no velocities, spins or history, and nothing of them is packed or scattered.
template <bool Periodic, bool Friction>
void World::force_range(int begin, int end, const ForceSink& out, ThreadAcc& acc) {
  const double dt = opt_.dt;
  const ContactParams law = law_;
  const double* R = p_.r.data();
  const int* J = nl_.j.data();
  Vec3* FS = nl_.fs.data();
  Vec3* MR = nl_.mr.data();
  std::uint8_t* TOUCH = nl_.touching.data();
  PairBatch b;
  int lanes = 0;  // a local, not b.count: the packing loop keeps it in a register
  auto flush = [&] {
    b.count = lanes;
    if constexpr (Friction)
      pair_batch_law(law, dt, b);
    else
      pair_batch_law<false, false, false>(law, dt, b);
    scatter_batch<Friction>(b, out, FS, MR, acc);
    lanes = 0;
  };

  // Plain doubles, not Vec3: the components go one by one into the batch's arrays
  // (through Eigen's 2 + 1 lane packing each took a shuffle; 0.5% of the run).
  const double* x = flat(p_.x);
  const double* v = flat(p_.v);
  const double* w = flat(p_.w);
  double* fs = flat(nl_.fs);
  double* mr = flat(nl_.mr);
  const int* S = nl_.start.data();
  for (int i = begin; i < end; ++i) {
    const double xi0 = x[3 * i], xi1 = x[3 * i + 1], xi2 = x[3 * i + 2];
    const double vi0 = v[3 * i], vi1 = v[3 * i + 1], vi2 = v[3 * i + 2];
    const double wi0 = w[3 * i], wi1 = w[3 * i + 1], wi2 = w[3 * i + 2];
    const double ri = R[i];
    // The bounds in locals: the byte store to TOUCH may alias anything, and would
    // make the compiler reload them for every candidate.
    const int e_end = S[i + 1];
    for (int e = S[i]; e < e_end; ++e) {
      const int j = J[e];
      // A candidate that did not touch at the last evaluation is tested on a path of
      // its own, and the path is chosen by that byte. Whether a candidate touches is a
      // coin toss to the branch predictor (58% of the 10,000-grain pack's entries do);
      // the byte, read from a sequential array, settles a mispredicted branch long
      // before the gathered positions would, and the distance tests on either path
      // almost always go the way they went last time (10,000 grains, one thread:
      // 75 -> 65 ns a particle-step; performance.md). Written as one test, GCC
      // merges the two paths and the gain is gone.
      if (!TOUCH[e]) {
        Vec3 d0(x[3 * j] - xi0, x[3 * j + 1] - xi1, x[3 * j + 2] - xi2);
        if constexpr (Periodic) dom_.min_image(d0);
        const double rs = ri + R[j];
        if (__builtin_expect(d0.squaredNorm() >= rs * rs, 1)) continue;
      }
      Vec3 d(x[3 * j] - xi0, x[3 * j + 1] - xi1, x[3 * j + 2] - xi2);
      if constexpr (Periodic) dom_.min_image(d);
      const double dist2 = d.squaredNorm();
      const double rj = R[j];
      const double rsum = ri + rj;
      if (dist2 >= rsum * rsum) {
        if (TOUCH[e]) {  // through fs and mr, as below: no second pointer walks the history
          fs[3 * e] = fs[3 * e + 1] = fs[3 * e + 2] = 0.0;
          mr[3 * e] = mr[3 * e + 1] = mr[3 * e + 2] = 0.0;
          TOUCH[e] = 0;
        }
        continue;
      }
      TOUCH[e] = 1;
      const int l = lanes++;
      b.i[l] = i;
      b.j[l] = j;
      b.e[l] = e;
      b.dx[l] = d.x();
      b.dy[l] = d.y();
      b.dz[l] = d.z();
      b.d2[l] = dist2;
      b.ri[l] = ri;
      b.rj[l] = rj;
      if constexpr (Friction) {
        b.vx[l] = vi0 - v[3 * j];
        b.vy[l] = vi1 - v[3 * j + 1];
        b.vz[l] = vi2 - v[3 * j + 2];
        b.wix[l] = wi0;
        b.wiy[l] = wi1;
        b.wiz[l] = wi2;
        b.wjx[l] = w[3 * j];
        b.wjy[l] = w[3 * j + 1];
        b.wjz[l] = w[3 * j + 2];
        b.fsx[l] = fs[3 * e];
        b.fsy[l] = fs[3 * e + 1];
        b.fsz[l] = fs[3 * e + 2];
        b.mrx[l] = mr[3 * e];
        b.mry[l] = mr[3 * e + 1];
        b.mrz[l] = mr[3 * e + 2];
      }
      if (lanes == kPairBatch) flush();
    }
  }
  if (lanes > 0) flush();
}

// Whether the lists of grains near each wall are out of date: the neighbour list was
// rebuilt since, or a wall has moved more than half the skin.
bool World::wall_candidates_stale() const {
  bool stale = nl_.builds() != wall_list_builds_ || wall_near_.size() != walls_.size();
  for (std::size_t w = 0; !stale && w < walls_.size(); ++w)
    stale = std::abs((walls_[w].point - wall_point_build_[w]).dot(walls_[w].normal)) > 0.5 * skin_;
  return stale;
}

void World::update_wall_candidates() {
  if (!wall_candidates_stale()) return;
  wall_near_.assign(walls_.size(), {});
  wall_point_build_.resize(walls_.size());
  for (std::size_t w = 0; w < walls_.size(); ++w) {
    wall_point_build_[w] = walls_[w].point;
    for (std::size_t i = 0; i < p_.size(); ++i) {
      const std::size_t slot = w * p_.size() + i;
      // Fixed grains never move: a wall acting on them does nothing but trip the
      // overlap check (floor grains beyond an infinite gate plane).
      if (!p_.fixed[i] && walls_[w].distance(p_.x[i]) < p_.r[i] + skin_) {
        wall_near_[w].push_back(static_cast<int>(i));
      } else {  // cannot be touching: a stale history would linger
        open_wall_contact(slot);
      }
    }
  }
  wall_list_builds_ = nl_.builds();
}

// Grain-wall contacts of the grains in [begin, end): only grains within the skin of a
// wall are tested. Each thread takes the same grain range it reduced the pair forces
// over, so it alone writes those grains' forces and no barrier is needed between
// walls; per-thread wall sums go to `part` and are added up in thread order after
// the parallel region (the result depends on the thread count, not on timing).
void World::wall_forces(int begin, int end, ThreadAcc& acc, WallPartial* part) {
  const double dt = opt_.dt;
  const ContactParams law = law_;
  const bool frictional = law.ks > 0.0, rolling = law.rolling();
  const std::size_t np = p_.size();
  for (std::size_t w = 0; w < walls_.size(); ++w) {
    const Wall& wall = walls_[w];
    WallPartial& sum = part[w];
    // The candidate list is in increasing grain order: this thread's part is one run.
    const std::vector<int>& near = wall_near_[w];
    const auto first = std::lower_bound(near.begin(), near.end(), begin);
    const auto last = std::lower_bound(first, near.end(), end);
    if (!(wall.frictional && frictional)) {
      smooth_wall_forces(w, near.data() + (first - near.begin()), near.data() + (last - near.begin()), acc, sum);
      continue;
    }
    for (auto it = first; it != last; ++it) {
      const int i = *it;
      const std::size_t slot = w * np + static_cast<std::size_t>(i);
      const double ri = p_.r[i];
      const double h = wall.active ? wall.distance(p_.x[i]) : ri;
      if (h >= ri) {
        open_wall_contact(slot);
        continue;
      }
      wall_touch_[slot] = 1;
      ContactKinematics k;
      k.n = -wall.normal;
      k.delta = ri - h;
      k.v_rel = p_.v[i] - wall.velocity + (h * p_.w[i]).cross(k.n);
      k.w_rel = p_.w[i];
      k.spin_n = 0.5 * p_.w[i].dot(k.n);
      k.r_roll = ri;
      const ContactResponse c = apply_contact_law(law, dt, k, wall_fs_[slot], wall_mr_[slot],
                                                  wall.frictional && frictional, wall.rolling && rolling);
      p_.f[i] += c.force;
      p_.t[i] += h * k.n.cross(c.fs) + wall_mr_[slot];
      sum.force += c.force;
      sum.contacts += 1;
      if (k.delta > acc.max_overlap * ri) {
        acc.max_overlap = k.delta / ri;
        acc.max_overlap_i = i;
      }
    }
  }
}

// Contacts with a smooth wall (the triaxial box's, and any wall while the law is
// frictionless): the normal spring alone, no torque. The same force, bit for bit,
// as the general law gives with the springs off, without its tangential and rolling
// kinematics (a smooth box had 11% of a 500-grain triaxial run in the general path).
void World::smooth_wall_forces(std::size_t w, const int* first, const int* last, ThreadAcc& acc,
                               WallPartial& sum) {
  // Everything the loop reads in locals: its stores through Vec3 pointers could
  // alias the wall and the arrays' bounds, which the compiler would reload per grain.
  const Wall& wall = walls_[w];
  const Vec3 normal = wall.normal, point = wall.point;
  const bool active = wall.active;
  const double kn = law_.kn;
  const std::size_t base = w * p_.size();
  const double* __restrict r = p_.r.data();
  const Vec3* __restrict x = p_.x.data();
  Vec3* __restrict f = p_.f.data();
  Vec3* fs = wall_fs_.data() + base;  // not restrict: open_wall_contact writes them too
  Vec3* mr = wall_mr_.data() + base;
  std::uint8_t* touch = wall_touch_.data() + base;
  Vec3 total = Vec3::Zero();
  int contacts = 0;
  double max_overlap = acc.max_overlap;
  int max_i = acc.max_overlap_i;
  for (const int* it = first; it != last; ++it) {
    const int i = *it;
    const double ri = r[i];
    const double h = active ? (x[i] - point).dot(normal) : ri;
    // The springs are kept at zero as the general law keeps them, in case this wall
    // or the law had friction before.
    if (h >= ri) {
      open_wall_contact(base + static_cast<std::size_t>(i));
      continue;
    }
    fs[i].setZero();
    mr[i].setZero();
    touch[i] = 1;
    const double delta = ri - h;
    const Vec3 force = (kn * delta) * normal;
    f[i] += force;
    total += force;
    ++contacts;
    if (delta > max_overlap * ri) {
      max_overlap = delta / ri;
      max_i = i;
    }
  }
  sum.force += total;
  sum.contacts += contacts;
  acc.max_overlap = max_overlap;
  acc.max_overlap_i = max_i;
}

// Gravity and (preparation only) local damping on the total force of grains [begin, end).
void World::external_forces(int begin, int end, ThreadAcc& acc) {
  const Vec3 g = opt_.gravity;
  const double alpha = opt_.local_damping;
  Vec3* __restrict f = p_.f.data();
  Vec3* __restrict t = p_.t.data();
  const Vec3* __restrict v = p_.v.data();
  const Vec3* __restrict w = p_.w.data();
  const double* __restrict m = p_.m.data();
  const std::uint8_t* __restrict fixed = p_.fixed.data();
  if (g.squaredNorm() > 0.0)
    for (int i = begin; i < end; ++i)
      if (!fixed[i]) f[i] += m[i] * g;
  if (alpha == 0.0) return;
  // The imbalance the damping is about to hide; a block's grains come in two runs.
  acc.net_force_sum += free_force_sum(begin, end);
  // Cundall's local damping, -alpha |F| sign(v) per component, with sign(v) written
  // as copysign times (v != 0): the direction of motion is an unpredictable branch.
  // The loop runs over the components as one flat array so that it vectorises; it
  // damps fixed grains' forces too, which moves nothing (1/m = 0) and is read by
  // nothing (the unbalanced-force ratio skips fixed grains).
  double* __restrict fc = f[0].data();
  double* __restrict tc = t[0].data();
  const double* __restrict vc = v[0].data();
  const double* __restrict wc = w[0].data();
  auto damp = [alpha](double force, double speed) {
    return force - alpha * std::copysign(std::abs(force), speed) * static_cast<double>(speed != 0.0);
  };
#pragma omp simd
  for (int k = 3 * begin; k < 3 * end; ++k) {
    fc[k] = damp(fc[k], vc[k]);
    tc[k] = damp(tc[k], wc[k]);
  }
}

// Sum of |F| over the free grains of [begin, end), as the force arrays hold it now.
double World::free_force_sum(int begin, int end) const {
  double sum = 0.0;
  for (int i = begin; i < end; ++i)
    if (!p_.fixed[i]) sum += p_.f[i].norm();
  return sum;
}

double World::net_force_sum() const {
  return damped_ ? net_force_sum_ : free_force_sum(0, static_cast<int>(p_.size()));
}

void World::compute_forces() { evaluate_forces(nl_.needs_rebuild(p_, dom_, skin_, opt_.threads), false); }

// Second half of velocity Verlet for grains [begin, end), whose forces are complete.
// Grains below `shared_end` are read by another thread's pair loop (prefetch_for_write).
void World::half_kick(int begin, int end, int shared_end, ThreadAcc& acc) {
  const double half = 0.5 * opt_.dt;
  const VerletArrays a(p_);
  // One sum over the range: a NaN or an infinity anywhere makes it non-finite, and
  // finite positions and speeds cannot overflow it. No test per grain, so no branch.
  double sum = 0.0;
  auto kick = [&](int i) {
    a.kick(i, half);
    sum += a.x[i].sum() + a.v[i].sum() + a.w[i].sum();
  };
  const int split = std::clamp(shared_end, begin, end);
  for (int i = begin; i < split; ++i) {
    const int ahead = std::min(i + kPrefetchAhead, split - 1);  // no pointer past the arrays
    prefetch_for_write(a.v + ahead);
    prefetch_for_write(a.w + ahead);
    kick(i);
  }
  for (int i = split; i < end; ++i) kick(i);
  acc.finite = acc.finite && std::isfinite(sum);  // a block is kicked in two runs
}

// Cuts the pair rows into one contiguous block per thread, balanced by list entries
// (plus a fixed cost per row), and finds how far above its block each block's
// pairs reach. Grains are in spatial order and the list is a half list (j > i), so
// a block's pairs touch the block and a boundary layer above it: each thread works
// on grains its own cache holds. (Interleaved chunks balanced as well, but every
// thread touched every grain, and the second thread's passes paid for the lines the
// first had written.) The list's row starts change only when it is rebuilt.
void World::assign_blocks() {
  const int n = static_cast<int>(p_.size());
  const int nt = opt_.threads;
  const int* S = nl_.start.data();
  const int* J = nl_.j.data();
  auto cost = [S](int i) { return static_cast<long long>(S[i]) + 2LL * i; };
  row_lo_.assign(static_cast<std::size_t>(nt) + 1, n);
  row_lo_[0] = 0;
  for (int t = 1; t < nt; ++t) {
    const long long target = cost(n) * t / nt;
    int a = row_lo_[t - 1], b = n;  // first row whose cumulative cost reaches the target
    while (a < b) {
      const int mid = a + (b - a) / 2;
      if (cost(mid) < target) a = mid + 1;
      else b = mid;
    }
    row_lo_[t] = a;
  }
  reach_.assign(static_cast<std::size_t>(nt), 0);
  for (int t = 0; t < nt; ++t) {
    int top = row_lo_[t + 1];
    for (int e = S[row_lo_[t]]; e < S[row_lo_[t + 1]]; ++e) top = std::max(top, J[e] + 1);
    reach_[t] = top;
  }
  shared_hi_.assign(static_cast<std::size_t>(nt), 0);
  for (int t = 0, top = 0; t < nt; ++t) {
    shared_hi_[t] = std::clamp(top, row_lo_[t], row_lo_[t + 1]);
    top = std::max(top, reach_[t]);
  }
  marks_.resize(static_cast<std::size_t>(nt));
  if (nt > 1)
    for (int t = 0; t < nt; ++t) {
      buf_f_[t].resize(p_.size(), Vec3::Zero());
      buf_t_[t].resize(p_.size(), Vec3::Zero());
    }
  blocks_builds_ = nl_.builds();
}

// Whether the blocks were cut for this many threads and grains (the list may have
// been rebuilt since).
bool World::blocks_fit() const {
  const std::size_t nt = static_cast<std::size_t>(opt_.threads);
  return row_lo_.size() == nt + 1 && row_lo_[nt] == static_cast<int>(p_.size());
}

// Whether the blocks must be cut again: the list was rebuilt since, or they do not fit.
bool World::blocks_stale() const { return nl_.builds() != blocks_builds_ || !blocks_fit(); }

// First grain of a thread's block: the blocks of the last force evaluation, or an
// even split before there are any.
int World::block_lo(int tid) const {
  if (blocks_fit()) return row_lo_[tid];
  return static_cast<int>(static_cast<long long>(p_.size()) * tid / opt_.threads);
}

// Block `blk`'s pair rows: its grains' forces cleared, then its pairs' forces on
// them written in place and those on grains above the block into its buffer,
// cleared first over the reach of its list entries. No thread writes another's
// block, so no barrier is needed before this.
void World::block_pairs(int blk, bool periodic, bool frictional) {
  const int lo = row_lo_[blk], hi = row_lo_[blk + 1], reach = reach_[blk];  // reach >= hi
  ForceSink out{p_.f.data(), p_.t.data(), p_.f.data(), p_.t.data(), hi};
  if (opt_.threads > 1) {
    out.buf_f = buf_f_[blk].data();
    out.buf_t = buf_t_[blk].data();
    std::fill(out.buf_f + hi, out.buf_f + reach, Vec3::Zero());
    std::fill(out.buf_t + hi, out.buf_t + reach, Vec3::Zero());
  }
  std::fill(p_.f.begin() + lo, p_.f.begin() + hi, Vec3::Zero());
  std::fill(p_.t.begin() + lo, p_.t.begin() + hi, Vec3::Zero());
  ThreadAcc& acc = acc_[blk];
  const int chunk = 64;  // rows per call: the batch flushes at the end of each
  for (int b = lo; b < hi; b += chunk) {
    const int e = std::min(hi, b + chunk);
    if (periodic)
      frictional ? force_range<true, true>(b, e, out, acc) : force_range<true, false>(b, e, out, acc);
    else
      frictional ? force_range<false, true>(b, e, out, acc) : force_range<false, false>(b, e, out, acc);
  }
}

// The lower blocks' buffered forces on block `blk`'s grains, in block order:
// deterministic for a thread count.
void World::add_lower_buffers(int blk) {
  const int lo = row_lo_[blk], hi = row_lo_[blk + 1];
  for (int s = 0; s < blk; ++s) {
    const Vec3* bf = buf_f_[s].data();
    const Vec3* bt = buf_t_[s].data();
    const int top = std::min(hi, reach_[s]);
    for (int i = std::max(lo, row_lo_[s + 1]); i < top; ++i) {
      p_.f[i] += bf[i];
      p_.t[i] += bt[i];
    }
  }
}

// One past the highest grain of block `blk` that a lower block's pairs reach (its
// first grain when none does, or before the blocks are cut).
int World::shared_hi(int blk) const { return blocks_fit() ? shared_hi_[blk] : block_lo(blk); }

// Waits until every block below `blk` whose pairs reach it has finished evaluation
// `eval`'s pair rows. Every thread runs all its blocks' pairs before it waits for
// any, so the marks it waits for are all on their way. A spin, yielding after a
// while: a barrier here made the upper block idle while the lower one finished.
void World::wait_for_lower_blocks(int blk, long eval) const {
  for (int s = 0; s < blk; ++s) {
    if (reach_[s] <= row_lo_[blk]) continue;
    for (int spins = 0; marks_[s].done.load(std::memory_order_acquire) < eval; ++spins)
      if (spins > 4096) std::this_thread::yield();
  }
}

// Serial set-up of a force evaluation: the list rebuilt when `rebuild`, the wall
// candidates, the blocks, and the per-thread sums cleared.
void World::begin_forces(bool rebuild, std::chrono::steady_clock::time_point& clock) {
  if (rebuild) nl_.build(p_, dom_, skin_, opt_.threads);
  update_wall_candidates();
  if (blocks_stale()) assign_blocks();
  times_.neighbor += seconds_since(clock);
  clear_thread_sums();
}

void World::clear_thread_sums() {
  ++evals_;
  acc_.assign(static_cast<std::size_t>(opt_.threads), ThreadAcc{});
  wall_part_.assign(static_cast<std::size_t>(opt_.threads) * walls_.size(), WallPartial{});
}

// One thread's share of a force evaluation, inside a parallel region. Each thread
// owns one block of grains: it clears their forces and runs their pair rows (forces
// on grains above the block go to its buffer) and marks the block done. Then it
// finishes the grains no lower block's pairs reach (wall contacts, external forces,
// with `kick` the second half-kick) while the lower blocks may still run, waits for
// their marks, adds their buffered forces and finishes the rest. No barrier: with
// one, the upper block sat idle while the lower one, which pays for reading the
// boundary grains from the other core, finished its pairs. Thread 0 alone reads and
// resets the clock.
void World::block_forces(bool kick, std::chrono::steady_clock::time_point& clock, double& t_pairs,
                         double& t_walls) {
  // One block per thread; a smaller team (a build without OpenMP, a thread limit)
  // takes the blocks in turn, so that every grain is still done.
  const int nt = opt_.threads, tid = thread_id(), team = team_size();
  const bool periodic = dom_.any_periodic();
  const bool frictional = law_.ks > 0.0;
  const long eval = evals_;
  for (int blk = tid; blk < nt; blk += team) {
    block_pairs(blk, periodic, frictional);
    marks_[blk].done.store(eval, std::memory_order_release);
  }
  if (tid == 0) t_pairs += seconds_since(clock);
  for (int blk = tid; blk < nt; blk += team) {
    const int lo = row_lo_[blk], hi = row_lo_[blk + 1], mid = shared_hi_[blk];
    // No lower block's pairs reach [mid, hi): those forces are complete already.
    finish_grains(blk, mid, hi, kick, tid, clock, t_walls);
    wait_for_lower_blocks(blk, eval);
    add_lower_buffers(blk);  // block 0, thread 0's, has none: its clock needs no mark here
    finish_grains(blk, lo, mid, kick, tid, clock, t_walls);
  }
}

// Grains [begin, end) of block `blk`, whose forces are complete: their wall
// contacts, external forces and (with `kick`) second half-kick.
void World::finish_grains(int blk, int begin, int end, bool kick, int tid,
                          std::chrono::steady_clock::time_point& clock, double& t_walls) {
  if (begin >= end) return;
  wall_forces(begin, end, acc_[blk], wall_part_.data() + static_cast<std::size_t>(blk) * walls_.size());
  if (tid == 0) t_walls += seconds_since(clock);
  external_forces(begin, end, acc_[blk]);
  if (kick) half_kick(begin, end, shared_hi_[blk], acc_[blk]);
}

// The threads' sums added up in block order (deterministic for a thread count).
// Returns whether all grains are finite.
bool World::end_forces(std::chrono::steady_clock::time_point& clock, double t_pairs, double t_walls) {
  const std::size_t nw = walls_.size();
  const int nt = opt_.threads;
  for (std::size_t w = 0; w < nw; ++w) {
    Wall& wall = walls_[w];
    wall.force.setZero();
    wall.contacts = 0;
    for (int t = 0; t < nt; ++t) {
      const WallPartial& part = wall_part_[static_cast<std::size_t>(t) * nw + w];
      wall.force -= part.force;
      wall.contacts += part.contacts;
    }
    wall.stiffness = wall.contacts * law_.kn;
  }
  max_overlap_ratio_ = 0.0;
  max_overlap_particle_ = -1;
  damped_ = opt_.local_damping > 0.0;
  net_force_sum_ = 0.0;
  bool finite = true;
  for (const auto& a : acc_) {
    finite = finite && a.finite;
    net_force_sum_ += a.net_force_sum;
    if (a.max_overlap > max_overlap_ratio_) {
      max_overlap_ratio_ = a.max_overlap;
      max_overlap_particle_ = a.max_overlap_i;
    }
  }
  times_.pairs += t_pairs;
  times_.walls += t_walls;
  times_.integrate += seconds_since(clock);
  forces_valid_ = true;
  return finite;
}

// One parallel region per force evaluation.
bool World::evaluate_forces(bool rebuild, bool kick) {
  auto clock = std::chrono::steady_clock::now();
  begin_forces(rebuild, clock);
  double t_pairs = 0.0, t_walls = 0.0;  // thread 0's view of the phases
#pragma omp parallel num_threads(opt_.threads)
  block_forces(kick, clock, t_pairs, t_walls);
  return end_forces(clock, t_pairs, t_walls);
}

// The first half-kick and the drift of block `blk`'s grains, with the Verlet-skin
// test folded in when there is a list for these grains (`listed`); returns whether
// some grain has used up half the skin. Periodic is a template argument so that the
// open box, the common case, tests no axis per grain.
template <bool Periodic>
bool World::drift_block(int blk, bool listed) {
  const double dt = opt_.dt, half = 0.5 * dt, skin = skin_;
  const Domain dom = dom_;
  const VerletArrays a(p_);
  const double* r = p_.r.data();
  const Vec3* xb = nl_.build_positions();
  const double* rb = nl_.build_radii();
  bool stale = false;
  const int shared_end = shared_hi(blk);
  for (int i = block_lo(blk), end = block_lo(blk + 1); i < end; ++i) {
    if (i < shared_end) {  // prefetch_for_write; a run at the block's start, predictable
      const int ahead = std::min(i + kPrefetchAhead, shared_end - 1);  // no pointer past the arrays
      prefetch_for_write(a.x + ahead);
      prefetch_for_write(a.v + ahead);
      prefetch_for_write(a.w + ahead);
    }
    a.kick(i, half);
    a.x[i] += dt * a.v[i];
    if constexpr (Periodic) dom.wrap(a.x[i]);
    if (!listed) continue;
    Vec3 d = a.x[i] - xb[i];
    if constexpr (Periodic) dom.min_image(d);
    stale |= NeighborList::moved_too_far(d, r[i], rb[i], skin);
  }
  return stale;
}

// The drift of every grain in a parallel region of its own. Each thread drifts the
// block whose forces it evaluated: the lines are in its cache.
template <bool Periodic>
bool World::drift(bool listed) {
  bool stale = false;
#pragma omp parallel num_threads(opt_.threads) reduction(|| : stale)
  for (int blk = thread_id(); blk < opt_.threads; blk += team_size()) stale |= drift_block<Periodic>(blk, listed);
  return stale;
}

// A whole step in one parallel region, for the common step that keeps its lists:
// each thread drifts its block, and after a barrier, unless some grain has used up
// half the skin, evaluates its block's forces and kicks it. One fork and join a step
// fewer than two regions: 2.5% on two threads at 2,000 grains (performance.md).
// Returns false, with every grain drifted and no forces evaluated, when the list
// must be rebuilt.
template <bool Periodic>
bool World::drift_and_forces(bool& finite) {
  auto clock = std::chrono::steady_clock::now();
  clear_thread_sums();
  const int nt = opt_.threads;
  bool rebuild = false;
  double t_pairs = 0.0, t_walls = 0.0;  // thread 0's view of the phases
#pragma omp parallel num_threads(nt)
  {
    const int tid = thread_id(), team = team_size();
    for (int blk = tid; blk < nt; blk += team) acc_[blk].stale = drift_block<Periodic>(blk, true);
#ifdef _OPENMP
#pragma omp barrier
#endif
    bool any = false;  // every thread reads the same flags, so all take the same branch
    for (int t = 0; t < nt; ++t) any = any || acc_[t].stale;
    if (tid == 0) {
      rebuild = any;
      times_.integrate += seconds_since(clock);
    }
    if (!any) block_forces(true, clock, t_pairs, t_walls);
  }
  if (rebuild) return false;
  finite = end_forces(clock, t_pairs, t_walls);
  return true;
}

// Usually one parallel region a step (drift_and_forces). A step that rebuilds a list
// takes two: the first half-kick and drift (with the Verlet-skin test folded in),
// then the force evaluation, which ends with each thread's second half-kick of the
// grains it reduced.
void World::step() {
  if (!forces_valid_) compute_forces();
  auto clock = std::chrono::steady_clock::now();
  const double dt = opt_.dt, half = 0.5 * dt;

  // Work done on the grains by moving walls over this step (trapezoidal rule).
  double wall_power_before = 0.0;
  for (const auto& wall : walls_) wall_power_before -= wall.force.dot(wall.velocity);
  // The walls move before the grains drift; the drift does not read them.
  for (auto& wall : walls_) wall.point += dt * wall.velocity;

  const bool periodic = dom_.any_periodic();
  const bool listed = nl_.built_for(p_.size());
  bool finite = true;
  bool done = false;
  if (listed && !blocks_stale() && !wall_candidates_stale()) {
    times_.integrate += seconds_since(clock);
    done = periodic ? drift_and_forces<true>(finite) : drift_and_forces<false>(finite);
    if (!done) finite = evaluate_forces(true, true);  // drifted; the list is stale
  } else {
    const bool moved = periodic ? drift<true>(listed) : drift<false>(listed);
    times_.integrate += seconds_since(clock);
    finite = evaluate_forces(!listed || moved, true);
  }

  double wall_power_after = 0.0;
  for (const auto& wall : walls_) wall_power_after -= wall.force.dot(wall.velocity);
  wall_work_ += half * (wall_power_before + wall_power_after);

  ++step_;
  time_ += dt;
  if (!finite) check_finite_and_overlap();
  if (max_overlap_ratio_ > opt_.max_overlap_fraction) check_finite_and_overlap();
  if (guard_tol_ >= 0.0 && step_ % guard_interval_ == 0) check_energy();
}

void World::check_finite_and_overlap() {
  for (std::size_t i = 0; i < p_.size(); ++i) {
    const char* what = nullptr;
    if (!std::isfinite(p_.x[i].sum())) what = "position";
    else if (!std::isfinite(p_.v[i].sum())) what = "velocity";
    else if (!std::isfinite(p_.w[i].sum())) what = "angular velocity";
    if (what) {
      std::ostringstream os;
      os << "unstable integration at step " << step_ << ": particle " << i << " has a non-finite " << what
         << " (dt = " << opt_.dt << " s)";
      throw InstabilityError(step_, static_cast<long>(i), what, os.str());
    }
  }
  if (max_overlap_ratio_ > opt_.max_overlap_fraction) {
    std::ostringstream os;
    os << "unstable integration at step " << step_ << ": particle " << max_overlap_particle_ << " overlaps by "
       << max_overlap_ratio_ << " of the smaller radius (limit " << opt_.max_overlap_fraction
       << "); the time step " << opt_.dt << " s is too large or the stiffness too low for the load";
    throw InstabilityError(step_, max_overlap_particle_, "overlap", os.str());
  }
}

double World::guard_energy() const {
  double e = 0.0;
  for (std::size_t i = 0; i < p_.size(); ++i) {
    if (p_.fixed[i]) continue;
    const double inertia = 0.4 * p_.m[i] * p_.r[i] * p_.r[i];
    e += 0.5 * p_.m[i] * p_.v[i].squaredNorm() + 0.5 * inertia * p_.w[i].squaredNorm();
    e -= p_.m[i] * opt_.gravity.dot(p_.x[i]);
  }
  for_each_contact([&](const ContactView& c) {
    e += contact_elastic_energy(law_, c.delta, c.fs, c.mr, c.r_roll);
  });
  return e;
}

void World::enable_energy_guard(double rel_tolerance, long interval) {
  if (!forces_valid_) compute_forces();
  guard_tol_ = rel_tolerance;
  guard_interval_ = std::max(1L, interval);
  guard_ref_ = guard_energy();
  guard_work_ref_ = wall_work_;
}

void World::check_energy() {
  const double e = guard_energy();
  const double input = wall_work_ - guard_work_ref_;
  const double scale = std::max({std::abs(guard_ref_), std::abs(input), 1e-300});
  const double excess = e - guard_ref_ - input;
  if (excess > guard_tol_ * scale) {
    long worst = -1;
    double worst_ke = -1.0;
    for (std::size_t i = 0; i < p_.size(); ++i) {
      const double ke = p_.m[i] * p_.v[i].squaredNorm();
      if (ke > worst_ke) {
        worst_ke = ke;
        worst = static_cast<long>(i);
      }
    }
    std::ostringstream os;
    os << "unstable integration at step " << step_ << ": total energy grew by " << excess / scale * 100.0
       << "% of its reference with no source of energy (limit " << guard_tol_ * 100.0
       << "%); fastest particle " << worst << "; dt = " << opt_.dt << " s";
    throw InstabilityError(step_, worst, "energy", os.str());
  }
}

}  // namespace demcal::engine
