#pragma once
// Statistics of a measured series whose successive samples are correlated (a
// stress ratio sampled every 0.1% of strain remembers its last few force chains):
// a mean with an honest standard error, and a linear trend with one.
#include <vector>

namespace demcal::engine {

struct MeanEstimate {
  double mean = 0;
  double se = 0;                 // standard error of the mean, correlation included
  double tau = 0.5;              // integrated autocorrelation time in samples (0.5: independent)
  double effective_samples = 0;  // n / (2 tau)
};

// Integrated autocorrelation time by Sokal's self-consistent window (the sum of
// autocorrelations stops at the first lag M >= 5 tau), corrected for the bias of
// autocorrelations about the sample mean, floored at 0.5 (a series cannot be more
// informative than independent samples); se = sd * sqrt(2 tau / n). On AR(1) series
// of 100 rows with tau = 4.5, mean +- 1.96 se covers the truth in 89% of series
// (tests/engine/test_series_stats.cpp): 10-odd effective samples cannot do better.
// Fewer than 2 samples: se = 0, effective_samples = n. A non-finite sample makes
// se, tau and effective_samples NaN.
MeanEstimate correlated_mean(const std::vector<double>& x);

struct Trend {
  bool ok = false;       // at least 3 points and x not all equal
  double slope = 0;      // dy/dx, least squares
  double intercept = 0;  // y at x = 0
  double se = 0;         // the slope's standard error, widened by the residuals' correlation
};
Trend linear_trend(const std::vector<double>& x, const std::vector<double>& y);

}  // namespace demcal::engine
