#pragma once
// Free-surface profile of a granular deposit and the angle of repose measured on it
// (seed Sec. 2.2.4). Pure functions: they see grain positions and radii, or a
// profile, never a World, so they are tested on synthetic heaps.
//
// Convention: x is the spreading direction, z is up, the deposit slopes down
// towards +x (the column stood against a back wall at small x).
#include "types.hpp"

#include <string>
#include <vector>

namespace demcal::engine {

// Heights of the free surface in bins of equal width along x.
struct SurfaceProfile {
  double x0 = 0.0;             // left edge of bin 0
  double bin = 0.0;            // bin width
  std::vector<double> x;       // bin centres
  std::vector<double> h;       // highest grain top (z + r) in the bin minus `base`; 0 when empty
  std::vector<int> count;      // grains whose centre lies in the bin
};

// Profile of the grains whose centres lie in [x_lo, x_hi); `include` (optional,
// same length as x) selects the grains, e.g. the mobile ones. Heights below the
// base are clamped to 0.
SurfaceProfile surface_profile(const std::vector<Vec3>& pos, const std::vector<double>& radius,
                               const std::vector<std::uint8_t>* include, double x_lo, double x_hi, double bin,
                               double base);

// Least-squares line through the slope between fractions [f_lo, f_hi] of the
// deposit height, crest and toe excluded.
struct SlopeFit {
  bool ok = false;
  std::string why;           // when !ok
  double h_max = 0.0;        // deposit height (maximum of the profile)
  double x_upper = 0.0;      // downstream-most bin at or above f_hi * h_max (start of the fitted slope)
  double x_lower = 0.0;      // downstream-most bin at or above f_lo * h_max (end of the fitted slope)
  int points = 0;            // bins used
  double slope = 0.0;        // dh/dx of the line (negative for a heap sloping to +x)
  double intercept = 0.0;    // h at x = 0
  double slope_se = 0.0;     // standard error of the slope, widened by the residuals' correlation
  double angle_deg = 0.0;    // atan(|slope|)
  double angle_err_deg = 0.0;  // standard error of the angle: se / (1 + slope^2)
  // The same fit over the upper and the lower half of the height range (split at
  // (f_lo + f_hi) / 2): the seed's error bars are two measurements at different
  // places on the slope, and a concave heap reads steeper near its crest. NaN when a
  // half holds fewer than 6 bins (the seed column's halves hold ~20; a quick
  // column's 4-5 bins give noise).
  double upper_angle_deg = 0.0, lower_angle_deg = 0.0;
};
SlopeFit fit_slope(const std::vector<double>& x, const std::vector<double>& h, double f_lo, double f_hi);

// Steepest local angle: the largest atan(|slope|) of least-squares lines through
// `window` consecutive bins lying inside [x_from, x_to] (the seed measures "the
// steepest angle of the deposit profile"). Returns 0 when fewer than `window`
// bins are available.
double steepest_angle_deg(const std::vector<double>& x, const std::vector<double>& h, double x_from, double x_to,
                          int window);

// Front of the deposit: scanning from bin index `start` towards +x, the last bin
// whose height is at least `min_height` before a run of more than `max_gap_bins`
// lower bins (isolated bouncers beyond such a gap are ignored). Returns the
// largest x + r of the grains in or behind that bin (exact front edge), or the
// bin's right edge when no grains are given. -1 index when no bin qualifies.
struct Front {
  int bin = -1;
  double x = 0.0;
};
Front deposit_front(const SurfaceProfile& prof, int start, double min_height, int max_gap_bins,
                    const std::vector<Vec3>* pos = nullptr, const std::vector<double>* radius = nullptr,
                    const std::vector<std::uint8_t>* include = nullptr);

// fit_slope over the deposit up to its front (the whole profile when there is no
// front). Grains beyond the front (at eta = 0 a sphere on the floor rolls on, and
// one may bounce off the end wall in mid-air) are no part of the slope: one of them
// as high as the crest's top fraction made the fit start past the deposit and fail.
SlopeFit fit_heap(const SurfaceProfile& prof, const Front& front, double f_lo, double f_hi);

// How concentrated the motion is: the fewest of the included grains whose kinetic
// energy (0.5 m v^2) makes up `share` of the total, and the fastest of them. A
// deposit that will not come to rest because a handful of grains rattle is told
// apart from one still flowing.
struct MotionCarriers {
  std::size_t carriers = 0;  // 0 when nothing moves
  std::size_t grains = 0;    // included grains
  long fastest = -1;         // index of the grain with the most kinetic energy
};
MotionCarriers motion_carriers(const std::vector<Vec3>& velocity, const std::vector<double>& mass,
                               const std::vector<std::uint8_t>& include, double share = 0.9);

// How far a heap moved over the samples of a collapse from time `from` on, from the
// front and fitted angle at each sample (time, front_x, angle_deg: one entry per
// sample). Not judged (and `why` says so) when the window would start before
// `earliest`, holds fewer than two samples (the least a job's window may span), or a
// sample in it has no angle (no heap to fit).
//
// The front is judged by its lower envelope: its lowest value in each sixth of the
// window, and how far those six values spread. A grain hopping at the toe, within the
// front's gap tolerance, sets the front for the samples it is beyond it (seen: 3.8
// and 10 mm, single samples or two in every five, while the fitted angle moved by
// 1e-7 deg), and nothing damps such grains; but a hop only ever moves the front
// outward, so the heap's own toe is the envelope. A toe that creeps or retreats moves
// it, unless it does so only within the window's last sixth; a grain that stays
// beyond the toe for a whole sixth moves it too (and the heap is not judged at rest).
struct HeapStillness {
  bool judged = false;
  std::string why;
  double since = 0;  // time of the window's first sample
  double angle_change_deg = 0;   // the angle's range over the window
  double front_change_m = 0;     // spread of the lowest fronts of the window's sixths
  double front_excursion_m = 0;  // the front's whole range over the window, excursions included
};
HeapStillness heap_stillness(const std::vector<double>& time, const std::vector<double>& front_x,
                             const std::vector<double>& angle_deg, double from, double earliest);

// For a heap found still over its last `window` seconds: the earliest sample time,
// not before `earliest`, from which every start would have been judged still, or NaN
// when the last window itself is not. Still from a start: the angle's range from it
// to the end within `angle_tol_deg`, and the front's lowest values in blocks of
// window/6 counted back from the end (the window's sixths; the block the start cuts
// counts from the start on) spread by no more than `front_tol_m`. One pass back from
// the end, stopping at the first start that is not still. A heap at rest by its
// profile came to rest then, not at the window's start (a heap still from 0.340 s
// read 1.005 s).
double still_since(const std::vector<double>& time, const std::vector<double>& front_x,
                   const std::vector<double>& angle_deg, double window, double earliest, double angle_tol_deg,
                   double front_tol_m);

// What makes a fitted angle no free slope's, in words for the run's warnings: a
// deposit under kMinHeapDiameters mean diameters high (a layer, whose line through the
// bins can read anything near 0: 0.28 +- 0.40 deg was stored with nothing said), a
// slope not told apart from flat (under two standard errors), or, when grains reached
// the end wall at `end_wall_x`, a slope whose foot is within two bins of it (the heap
// leans on the wall: 21.8 deg was warned only that the runout was bounded).
constexpr double kMinHeapDiameters = 3.0;
std::vector<std::string> slope_doubts(const SlopeFit& fit, double d_mean, double bin, double end_wall_x,
                                      bool reached_end_wall);

}  // namespace demcal::engine
