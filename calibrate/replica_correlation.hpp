#pragma once
// How the replica noise of two metrics of one job moves together. Both come from
// the same packings: a packing that reads strong at the peak tends to read strong at
// critical state too (measured on the seed study: rho = 0.33 over 126 degrees of
// freedom between phi_peak and phi_cv). Counting two such targets as independent
// overstates what they pin down along the direction where they err together.
#include "response_surface.hpp"

#include <string>

namespace demcal::calibrate {

struct ReplicaCorrelation {
  double rho = 0;      // the pooled within-point correlation; 0 when not estimated
  int dof = 0;         // degrees of freedom behind it: sum over points of (paired replicas - 1)
  int points = 0;      // grid points with at least two paired replicas
  bool estimated = false;
  std::string reason;  // why not, when not estimated
};

// Fewer degrees of freedom than this and the correlation is not estimated (taken as 0).
constexpr int kMinCorrelationDof = 5;
// A sample correlation near +-1 from few points would make two targets one; capped.
constexpr double kMaxCorrelation = 0.95;

// Pairs the two surfaces' values by task (the same packing and run gives both) and
// pools, over grid points, the replicas' deviations from each point's mean:
// rho = sum(da db) / sqrt(sum(da^2) sum(db^2)). Surfaces of different jobs come from
// different packings and are not correlated (estimated = false, rho = 0).
ReplicaCorrelation replica_correlation(const ResponseSurface& a, const ResponseSurface& b);

}  // namespace demcal::calibrate
