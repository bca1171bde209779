#include "repose_profile.hpp"

#include "series_stats.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

namespace demcal::engine {
namespace {

// Least-squares slope of h over x (NaN when x does not vary): for the halves and
// the steepest window, which need no error.
double slope_of(const double* x, const double* h, int n) {
  if (n < 2) return NAN;
  double mx = 0, mh = 0;
  for (int i = 0; i < n; ++i) {
    mx += x[i];
    mh += h[i];
  }
  mx /= n;
  mh /= n;
  double sxx = 0, sxh = 0;
  for (int i = 0; i < n; ++i) {
    sxx += (x[i] - mx) * (x[i] - mx);
    sxh += (x[i] - mx) * (h[i] - mh);
  }
  return sxx > 0.0 ? sxh / sxx : NAN;
}

// The bins of [i_up, i_low] whose heights lie in [bottom, top].
void select_between(const std::vector<double>& x, const std::vector<double>& h, int i_up, int i_low, double bottom,
                    double top, std::vector<double>& xs, std::vector<double>& hs) {
  for (int i = i_up; i <= i_low; ++i) {
    if (h[i] < bottom || h[i] > top) continue;
    xs.push_back(x[i]);
    hs.push_back(h[i]);
  }
}

double angle_between(const std::vector<double>& x, const std::vector<double>& h, int i_up, int i_low, double bottom,
                     double top) {
  std::vector<double> xs, hs;
  select_between(x, h, i_up, i_low, bottom, top, xs, hs);
  // A line through a handful of bins of a rough profile is noise (the quick column's
  // halves of 4-5 bins read 9-31 deg around a 25 deg heap): no angle below 6.
  if (xs.size() < 6) return NAN;
  const double slope = slope_of(xs.data(), hs.data(), static_cast<int>(xs.size()));
  return std::isfinite(slope) ? rad_to_deg(std::atan(std::abs(slope))) : NAN;
}

}  // namespace

SurfaceProfile surface_profile(const std::vector<Vec3>& pos, const std::vector<double>& radius,
                               const std::vector<std::uint8_t>* include, double x_lo, double x_hi, double bin,
                               double base) {
  SurfaceProfile p;
  p.x0 = x_lo;
  p.bin = bin;
  if (!(bin > 0.0) || !(x_hi > x_lo)) return p;
  const int n = std::max(1, static_cast<int>(std::ceil((x_hi - x_lo) / bin)));
  p.x.resize(n);
  p.h.assign(n, 0.0);
  p.count.assign(n, 0);
  for (int b = 0; b < n; ++b) p.x[b] = x_lo + (b + 0.5) * bin;
  for (std::size_t i = 0; i < pos.size(); ++i) {
    if (include && !(*include)[i]) continue;
    const double xi = pos[i][0];
    if (xi < x_lo || xi >= x_hi) continue;
    const int b = std::min(n - 1, static_cast<int>((xi - x_lo) / bin));
    p.count[b] += 1;
    p.h[b] = std::max(p.h[b], pos[i][2] + radius[i] - base);
  }
  return p;
}

SlopeFit fit_slope(const std::vector<double>& x, const std::vector<double>& h, double f_lo, double f_hi) {
  SlopeFit f;
  const int n = static_cast<int>(std::min(x.size(), h.size()));
  int i_max = 0;
  for (int i = 1; i < n; ++i)
    if (h[i] >= h[i_max]) i_max = i;  // ties: the downstream-most maximum
  if (n > 0) f.h_max = h[i_max];  // the deposit's height, reported even without a slope
  if (n < 3) {
    f.why = "profile has fewer than 3 bins";
    return f;
  }
  if (!(f.h_max > 0.0)) {
    f.why = "empty profile";
    return f;
  }
  const double top = f_hi * f.h_max, bottom = f_lo * f.h_max;
  // Upper end of the slope: the downstream-most bin still at or above the top
  // fraction (the crest and any plateau behind it lie upstream of it).
  int i_up = i_max;
  for (int i = n - 1; i >= i_max; --i)
    if (h[i] >= top) {
      i_up = i;
      break;
    }
  // Lower end: walk downstream until the profile drops below the bottom fraction
  // (the toe and anything beyond it are excluded).
  int i_low = i_up;
  while (i_low + 1 < n && h[i_low + 1] >= bottom) ++i_low;
  f.x_upper = x[i_up];
  f.x_lower = x[i_low];
  std::vector<double> xs, hs;
  select_between(x, h, i_up, i_low, bottom, top, xs, hs);
  f.points = static_cast<int>(xs.size());
  if (f.points < 3) {
    f.why = "fewer than 3 profile bins between the fit fractions";
    return f;
  }
  // Neighbouring bins share grains and the heap is not quite straight: residuals are
  // correlated, and the regression's own error would count them as independent.
  const Trend l = linear_trend(xs, hs);
  if (!l.ok) {
    f.why = "degenerate fit";
    return f;
  }
  f.ok = true;
  f.slope = l.slope;
  f.intercept = l.intercept;
  f.slope_se = l.se;
  f.angle_deg = rad_to_deg(std::atan(std::abs(l.slope)));
  f.angle_err_deg = rad_to_deg(f.slope_se / (1.0 + l.slope * l.slope));
  const double mid = 0.5 * (top + bottom);
  f.upper_angle_deg = angle_between(x, h, i_up, i_low, mid, top);
  f.lower_angle_deg = angle_between(x, h, i_up, i_low, bottom, mid);
  return f;
}

double steepest_angle_deg(const std::vector<double>& x, const std::vector<double>& h, double x_from, double x_to,
                          int window) {
  std::vector<double> xs, hs;
  for (std::size_t i = 0; i < std::min(x.size(), h.size()); ++i)
    if (x[i] >= x_from && x[i] <= x_to) {
      xs.push_back(x[i]);
      hs.push_back(h[i]);
    }
  const int n = static_cast<int>(xs.size());
  window = std::max(2, window);
  double best = 0.0;
  for (int s = 0; s + window <= n; ++s) {
    const double slope = slope_of(xs.data() + s, hs.data() + s, window);
    if (std::isfinite(slope)) best = std::max(best, rad_to_deg(std::atan(std::abs(slope))));
  }
  return best;
}

SlopeFit fit_heap(const SurfaceProfile& prof, const Front& front, double f_lo, double f_hi) {
  const std::size_t n = std::min(prof.x.size(), prof.h.size());
  const std::size_t upto = front.bin >= 0 ? std::min(n, static_cast<std::size_t>(front.bin) + 1) : n;
  const std::vector<double> x(prof.x.begin(), prof.x.begin() + static_cast<long>(upto));
  const std::vector<double> h(prof.h.begin(), prof.h.begin() + static_cast<long>(upto));
  return fit_slope(x, h, f_lo, f_hi);
}

Front deposit_front(const SurfaceProfile& prof, int start, double min_height, int max_gap_bins,
                    const std::vector<Vec3>* pos, const std::vector<double>* radius,
                    const std::vector<std::uint8_t>* include) {
  Front f;
  const int n = static_cast<int>(prof.h.size());
  int gap = 0;
  for (int b = std::max(0, start); b < n; ++b) {
    if (prof.h[b] >= min_height) {
      f.bin = b;
      gap = 0;
    } else if (f.bin >= 0 && ++gap > max_gap_bins) {
      break;
    }
  }
  if (f.bin < 0) return f;
  const double edge = prof.x0 + (f.bin + 1) * prof.bin;
  f.x = edge;
  if (pos && radius) {
    double front = -1e300;
    for (std::size_t i = 0; i < pos->size(); ++i) {
      if (include && !(*include)[i]) continue;
      const double xi = (*pos)[i][0];
      if (xi < prof.x0 || xi >= edge) continue;
      front = std::max(front, xi + (*radius)[i]);
    }
    if (front > -1e300) f.x = front;
  }
  return f;
}

MotionCarriers motion_carriers(const std::vector<Vec3>& velocity, const std::vector<double>& mass,
                               const std::vector<std::uint8_t>& include, double share) {
  std::vector<std::pair<double, std::size_t>> ke;
  double total = 0.0;
  for (std::size_t i = 0; i < velocity.size(); ++i)
    if (include[i]) {
      ke.push_back({0.5 * mass[i] * velocity[i].squaredNorm(), i});
      total += ke.back().first;
    }
  MotionCarriers c;
  c.grains = ke.size();
  if (!(total > 0.0)) return c;
  std::sort(ke.begin(), ke.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
  c.fastest = static_cast<long>(ke.front().second);
  for (double sum = 0.0; c.carriers < ke.size() && sum < share * total; ++c.carriers) sum += ke[c.carriers].first;
  return c;
}

HeapStillness heap_stillness(const std::vector<double>& time, const std::vector<double>& front_x,
                             const std::vector<double>& angle_deg, double from, double earliest) {
  HeapStillness h;
  if (from < earliest) {
    h.why = "its window starts before min_collapse_time";
    return h;
  }
  double a_lo = INFINITY, a_hi = -INFINITY;
  std::vector<double> fronts;
  for (std::size_t i = 0; i < time.size(); ++i) {
    if (time[i] < from) continue;
    if (!std::isfinite(angle_deg[i])) {
      h.why = "no slope could be fitted to it at " + std::to_string(time[i]) + " s";
      return h;
    }
    if (fronts.empty()) h.since = time[i];
    a_lo = std::min(a_lo, angle_deg[i]), a_hi = std::max(a_hi, angle_deg[i]);
    fronts.push_back(front_x[i]);
  }
  if (fronts.size() < 2) {
    h.why = "its window holds fewer than two samples";
    return h;
  }
  h.judged = true;
  h.angle_change_deg = a_hi - a_lo;
  // The lowest front of each sixth of the window (of each sample in a shorter one).
  const std::size_t n = fronts.size(), parts = std::min<std::size_t>(6, n);
  double lo = INFINITY, hi = -INFINITY;
  for (std::size_t k = 0; k < parts; ++k) {
    const auto first = fronts.begin() + static_cast<long>(k * n / parts);
    const auto last = fronts.begin() + static_cast<long>((k + 1) * n / parts);
    const double envelope = *std::min_element(first, last);
    lo = std::min(lo, envelope), hi = std::max(hi, envelope);
  }
  h.front_change_m = hi - lo;
  h.front_excursion_m = *std::max_element(fronts.begin(), fronts.end()) - *std::min_element(fronts.begin(), fronts.end());
  return h;
}

double still_since(const std::vector<double>& time, const std::vector<double>& front_x,
                   const std::vector<double>& angle_deg, double window, double earliest, double angle_tol_deg,
                   double front_tol_m) {
  const std::size_t n = std::min({time.size(), front_x.size(), angle_deg.size()});
  if (n < 2 || !(window > 0.0)) return NAN;
  const double end = time[n - 1], block = window / 6.0, from = end - window;
  // Walked back from the end: the angle's range, the lowest front of each finished
  // block (f_lo, f_hi: their spread) and of the block being walked (b_min).
  double a_lo = INFINITY, a_hi = -INFINITY, f_lo = INFINITY, f_hi = -INFINITY, b_min = INFINITY;
  long k = 0;
  double since = NAN;
  for (std::size_t i = n; i-- > 0;) {
    const double t = time[i];
    const bool in_window = t >= from;
    if (t < earliest || !std::isfinite(angle_deg[i])) return in_window ? NAN : since;
    // A sample on a block's edge joins the later block: the window's first sample is
    // in its earliest sixth, not a block of its own.
    const long kb = std::max(0L, static_cast<long>(std::floor((end - t) / block - 1e-9)));
    if (kb > k) {
      f_lo = std::min(f_lo, b_min), f_hi = std::max(f_hi, b_min);
      b_min = INFINITY;
      k = kb;
    }
    a_lo = std::min(a_lo, angle_deg[i]), a_hi = std::max(a_hi, angle_deg[i]);
    b_min = std::min(b_min, front_x[i]);
    const bool still = a_hi - a_lo <= angle_tol_deg && std::max(f_hi, b_min) - std::min(f_lo, b_min) <= front_tol_m;
    if (in_window) {
      since = still ? t : NAN;  // the window is judged whole, at its first sample
      continue;
    }
    if (!still || std::isnan(since)) break;
    since = t;
  }
  return since;
}

std::vector<std::string> slope_doubts(const SlopeFit& fit, double d_mean, double bin, double end_wall_x,
                                      bool reached_end_wall) {
  std::vector<std::string> doubts;
  if (!fit.ok) return doubts;
  std::ostringstream os;
  if (fit.h_max < kMinHeapDiameters * d_mean) {
    os << "the deposit is " << fit.h_max / d_mean << " mean diameters high (below " << kMinHeapDiameters
       << "): a layer of grains, not a heap, and its fitted angle is not an angle of repose (a taller "
       << "repose.column_height, or more friction or rolling resistance)";
    doubts.push_back(os.str());
  } else if (std::abs(fit.angle_deg) < 2.0 * fit.angle_err_deg) {
    os << "the fitted slope, " << fit.angle_deg << " +- " << fit.angle_err_deg
       << " deg, is not told apart from flat (under two standard errors)";
    doubts.push_back(os.str());
  }
  if (reached_end_wall && fit.x_lower + 2.0 * bin >= end_wall_x) {
    std::ostringstream wall;
    wall << "the fitted slope's foot, at " << fit.x_lower << " m, is within two bins of the end wall at " << end_wall_x
         << " m: the heap leans on the wall, and its angle is not a free slope's (a longer repose.domain_length)";
    doubts.push_back(wall.str());
  }
  return doubts;
}

}  // namespace demcal::engine
