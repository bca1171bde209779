#include "series_stats.hpp"

#include <algorithm>
#include <cmath>

namespace demcal::engine {
namespace {

double autocorrelation_time(const std::vector<double>& x, double mean) {
  const std::size_t n = x.size();
  double c0 = 0.0;
  for (double v : x) c0 += (v - mean) * (v - mean);
  if (!std::isfinite(c0)) return NAN;  // a NaN or infinite sample: no time to speak of
  if (c0 <= 0.0) return 0.5;
  double tau = 0.5;
  std::size_t window = 0;
  for (std::size_t k = 1; k < n; ++k) {
    double ck = 0.0;
    for (std::size_t i = 0; i + k < n; ++i) ck += (x[i] - mean) * (x[i + k] - mean);
    tau += ck / c0;
    window = k;
    if (static_cast<double>(k) >= 5.0 * tau) break;
  }
  // Autocorrelations about the sample's own mean are biased low, by about
  // (2M + 1) / n of tau for a window of M lags (Madras & Sokal 1988).
  tau *= 1.0 + static_cast<double>(2 * window + 1) / static_cast<double>(n);
  return std::max(0.5, tau);
}

}  // namespace

MeanEstimate correlated_mean(const std::vector<double>& x) {
  MeanEstimate e;
  const std::size_t n = x.size();
  if (n == 0) return e;
  for (double v : x) e.mean += v;
  e.mean /= static_cast<double>(n);
  e.effective_samples = static_cast<double>(n);
  if (n < 2) return e;
  double var = 0.0;
  for (double v : x) var += (v - e.mean) * (v - e.mean);
  var /= static_cast<double>(n - 1);
  e.tau = autocorrelation_time(x, e.mean);
  e.effective_samples = static_cast<double>(n) / (2.0 * e.tau);
  e.se = std::sqrt(var / e.effective_samples);
  return e;
}

Trend linear_trend(const std::vector<double>& x, const std::vector<double>& y) {
  Trend t;
  const std::size_t n = std::min(x.size(), y.size());
  if (n < 3) return t;
  double mx = 0.0, my = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    mx += x[i];
    my += y[i];
  }
  mx /= static_cast<double>(n);
  my /= static_cast<double>(n);
  double sxx = 0.0, sxy = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    sxx += (x[i] - mx) * (x[i] - mx);
    sxy += (x[i] - mx) * (y[i] - my);
  }
  if (sxx <= 0.0) return t;
  t.ok = true;
  t.slope = sxy / sxx;
  t.intercept = my - t.slope * mx;
  std::vector<double> resid(n);
  double rss = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    resid[i] = y[i] - my - t.slope * (x[i] - mx);
    rss += resid[i] * resid[i];
  }
  const double tau = autocorrelation_time(resid, 0.0);
  t.se = std::sqrt(rss / static_cast<double>(n - 2) / sxx * 2.0 * tau);
  return t;
}

}  // namespace demcal::engine
