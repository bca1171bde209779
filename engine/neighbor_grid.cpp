#include "neighbor_grid.hpp"

#include "errors.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <sstream>
#ifdef _OPENMP
#include <omp.h>
#endif

namespace demcal::engine {
namespace {

struct Grid {
  Vec3 origin;
  Vec3 cell;  // cell edge per axis
  std::array<int, 3> n{1, 1, 1};
  std::array<bool, 3> periodic{false, false, false};

  int axis_index(double x, int a) const {
    int c = static_cast<int>(std::floor((x - origin[a]) / cell[a]));
    if (periodic[a]) {
      c %= n[a];
      if (c < 0) c += n[a];
      return c;
    }
    return std::clamp(c, 0, n[a] - 1);
  }
  int index(const Vec3& x) const {
    return (axis_index(x[2], 2) * n[1] + axis_index(x[1], 1)) * n[0] + axis_index(x[0], 0);
  }
};

Grid make_grid(const Particles& p, const Domain& dom, double reach) {
  Grid g;
  Vec3 lo = Vec3::Constant(1e300), hi = Vec3::Constant(-1e300);
  for (const Vec3& x : p.x) {
    lo = lo.cwiseMin(x);
    hi = hi.cwiseMax(x);
  }
  for (int a = 0; a < 3; ++a) {
    g.periodic[a] = dom.periodic[a];
    if (dom.periodic[a]) {
      const double len = dom.length(a);
      if (len < 2.0 * reach) {
        std::ostringstream os;
        os << "periodic length " << len << " m on axis " << a << " is shorter than twice the interaction reach "
           << reach << " m (largest diameter plus skin)";
        throw ConfigError("domain.periodic", os.str());
      }
      g.origin[a] = dom.lo[a];
      g.n[a] = std::max(1, static_cast<int>(std::floor(len / reach)));
      g.cell[a] = len / g.n[a];
    } else {
      g.origin[a] = lo[a];
      const double extent = std::max(hi[a] - lo[a], reach);
      g.n[a] = std::max(1, static_cast<int>(std::floor(extent / reach)));
      g.cell[a] = std::max(extent / g.n[a], reach);
    }
  }
  // A sparse cloud spread far would make the dense grid huge: coarsen it.
  const double max_cells = 8.0 * static_cast<double>(p.size()) + 4096.0;
  while (static_cast<double>(g.n[0]) * g.n[1] * g.n[2] > max_cells) {
    for (int a = 0; a < 3; ++a) {
      if (g.periodic[a] || g.n[a] == 1) continue;
      g.n[a] = std::max(1, g.n[a] / 2);
      g.cell[a] *= 2.0;
    }
  }
  return g;
}

// Offsets of the distinct neighbour cells of cell (cx, cy, cz), itself included.
int neighbour_cells(const Grid& g, int cx, int cy, int cz, int* out) {
  int count = 0;
  int axes[3][3] = {}, na[3] = {};
  const int c[3] = {cx, cy, cz};
  for (int a = 0; a < 3; ++a) {
    na[a] = 0;
    for (int d = -1; d <= 1; ++d) {
      int v = c[a] + d;
      if (g.periodic[a]) {
        v = (v % g.n[a] + g.n[a]) % g.n[a];
      } else if (v < 0 || v >= g.n[a]) {
        continue;
      }
      bool seen = false;
      for (int k = 0; k < na[a]; ++k) seen |= (axes[a][k] == v);
      if (!seen) axes[a][na[a]++] = v;
    }
  }
  for (int z = 0; z < na[2]; ++z)
    for (int y = 0; y < na[1]; ++y)
      for (int x = 0; x < na[0]; ++x) out[count++] = (axes[2][z] * g.n[1] + axes[1][y]) * g.n[0] + axes[0][x];
  return count;
}

// Particles sorted into the grid's cells by a counting sort (stable: the order
// within a cell is the grains' order, so the list is deterministic).
struct CellSort {
  std::vector<int> cell_of, cell_start, items;
};

CellSort sort_into_cells(const Particles& p, const Grid& g) {
  const int n = static_cast<int>(p.size());
  CellSort cs{std::vector<int>(n), std::vector<int>(g.n[0] * g.n[1] * g.n[2] + 1, 0), std::vector<int>(n)};
  for (int i = 0; i < n; ++i) {
    cs.cell_of[i] = g.index(p.x[i]);
    ++cs.cell_start[cs.cell_of[i] + 1];
  }
  std::partial_sum(cs.cell_start.begin(), cs.cell_start.end(), cs.cell_start.begin());
  std::vector<int> fill(cs.cell_start.begin(), cs.cell_start.end() - 1);
  for (int i = 0; i < n; ++i) cs.items[fill[cs.cell_of[i]]++] = i;
  return cs;
}

// Appends to `out` the candidates j > i of grain i within reach (radii plus skin),
// sorted by j, and returns how many.
int candidate_row(const Particles& p, const Domain& dom, const Grid& g, const CellSort& cs, double skin, int i,
                  std::vector<int>& out) {
  int cells[27];
  const int c = cs.cell_of[i];
  const int cx = c % g.n[0], cy = (c / g.n[0]) % g.n[1], cz = c / (g.n[0] * g.n[1]);
  const int nc = neighbour_cells(g, cx, cy, cz, cells);
  const std::size_t row_begin = out.size();
  for (int k = 0; k < nc; ++k) {
    for (int s = cs.cell_start[cells[k]]; s < cs.cell_start[cells[k] + 1]; ++s) {
      const int jj = cs.items[s];
      if (jj <= i || (p.fixed[i] && p.fixed[jj])) continue;
      Vec3 d = p.x[jj] - p.x[i];
      dom.min_image(d);
      const double reach = p.r[i] + p.r[jj] + skin;
      if (d.squaredNorm() < reach * reach) out.push_back(jj);
    }
  }
  std::sort(out.begin() + static_cast<long>(row_begin), out.end());
  return static_cast<int>(out.size() - row_begin);
}

}  // namespace

void NeighborList::build(const Particles& p, const Domain& dom, double skin, int threads) {
  const int n = static_cast<int>(p.size());
  const double rmax = n ? *std::max_element(p.r.begin(), p.r.end()) : 0.0;
  const Grid g = make_grid(p, dom, 2.0 * rmax + skin);
  const CellSort cells = sort_into_cells(p, g);

  // New rows, one per particle; each thread fills the rows of its static share in
  // order, so concatenating the threads' parts gives the rows in grain order.
  std::vector<int> counts(n + 1, 0);
  std::vector<std::vector<int>> chunk_j(std::max(1, threads));
#pragma omp parallel num_threads(std::max(1, threads))
  {
    int tid = 0;
#ifdef _OPENMP
    tid = omp_get_thread_num();
#endif
#pragma omp for schedule(static)
    for (int i = 0; i < n; ++i) counts[i + 1] = candidate_row(p, dom, g, cells, skin, i, chunk_j[tid]);
  }
  std::vector<int> new_start(n + 1, 0);
  std::partial_sum(counts.begin(), counts.end(), new_start.begin());
  std::vector<int> new_j;
  new_j.reserve(new_start[n]);
  for (auto& c : chunk_j) new_j.insert(new_j.end(), c.begin(), c.end());

  carry_history(new_start, new_j, threads);
  start.swap(new_start);
  j.swap(new_j);
  x_build_ = p.x;
  r_build_ = p.r;
  ++builds_;
}

// The history of contacts live in the old list moves to the same pair in the new
// one (rows merged by j); pairs new to the list start untouched.
void NeighborList::carry_history(const std::vector<int>& new_start, const std::vector<int>& new_j, int threads) {
  const int n = static_cast<int>(new_start.size()) - 1;
  std::vector<Vec3> new_fs(new_j.size(), Vec3::Zero()), new_mr(new_j.size(), Vec3::Zero());
  std::vector<std::uint8_t> new_touch(new_j.size(), 0);
  if (static_cast<int>(start.size()) == n + 1) {
#pragma omp parallel for schedule(static) num_threads(std::max(1, threads))
    for (int i = 0; i < n; ++i) {
      int a = start[i], ae = start[i + 1];
      for (int b = new_start[i]; b < new_start[i + 1]; ++b) {
        while (a < ae && j[a] < new_j[b]) ++a;
        if (a < ae && j[a] == new_j[b] && touching[a]) {
          new_fs[b] = fs[a];
          new_mr[b] = mr[a];
          new_touch[b] = 1;
        }
      }
    }
  }
  fs.swap(new_fs);
  mr.swap(new_mr);
  touching.swap(new_touch);
}

bool NeighborList::needs_rebuild(const Particles& p, const Domain& dom, double skin, int threads) const {
  if (!built_for(p.size())) return true;
  // A pair can close by the displacement of each grain plus the growth of each
  // radius since the build: rebuild when either side may have used half the skin.
  const long n = static_cast<long>(p.size());
  bool stale = false;
#pragma omp parallel for schedule(static) num_threads(std::max(1, threads)) reduction(|| : stale)
  for (long i = 0; i < n; ++i) {
    Vec3 d = p.x[i] - x_build_[i];
    dom.min_image(d);
    stale = stale || moved_too_far(d, p.r[i], r_build_[i], skin);
  }
  return stale;
}

}  // namespace demcal::engine
