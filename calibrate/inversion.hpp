#pragma once
// The inverse fit: targets for some metrics in, the (theta, eta) whose surrogates
// match them best out, with the region consistent with the targets, warnings when
// the targets do not pin the parameters down, and a refusal (not a boundary point)
// when a target lies beyond what the grid reaches.
#include "replica_correlation.hpp"
#include "surrogate.hpp"

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace demcal::calibrate {

struct Target {
  std::string metric;
  double value = kNaN;
  double sigma = kNaN;  // the target's own uncertainty (a laboratory's), given by the user; NaN: exact
};

// "phi_peak=41.4" -> {phi_peak, 41.4}. Throws JobError(field) when malformed.
Target parse_target(const std::string& text, const std::string& field = "--target");
// "phi_peak=0.5" sets the sigma of that target; throws JobError("--sigma") when
// malformed, not positive, or naming no target.
void apply_sigma(std::vector<Target>& targets, const std::string& text);

// One metric's surrogate and what goes into its uncertainty.
struct Model {
  std::string metric, label, job;
  Surrogate surrogate;
  double replica_se = 0;
};

// The surrogate's error against the mean response it stands for: its LOO error with
// the noise of a point's own mean taken out, at least the noise the surface carries.
double surrogate_error(const Surrogate& s, double replica_se);

struct TargetFit {
  std::string metric, job;
  double target = kNaN, sigma = kNaN;  // sigma^2 = lab_sigma^2 + surrogate_sigma^2 (floored)
  double lab_sigma = 0, surrogate_sigma = kNaN;
  // The part of surrogate_sigma that is replica noise carried by the surface
  // (sqrt(mean leverage) x replica se): the part shared, through the packings, with
  // other metrics of the same job.
  double noise_sigma = 0;
  bool sigma_given = false;
  double predicted = kNaN, residual = kNaN;  // residual = predicted - target
  double loo_rms = kNaN, replica_se = kNaN;
  double lo = kNaN, hi = kNaN;  // the surrogate's range over the box
  double theta_at_lo = kNaN, eta_at_lo = kNaN, theta_at_hi = kNaN, eta_at_hi = kNaN;
};

// The replica correlation between targets k < l (both metrics of one job).
struct PairCorrelation {
  std::size_t k = 0, l = 0;
  ReplicaCorrelation c;
  // The correlation of the two surrogates' noise at the best point: rho times the
  // cosine between their hat vectors there (set by invert when counted).
  double at_best = kNaN;
};

struct Region {
  double theta_lo = kNaN, theta_hi = kNaN, eta_lo = kNaN, eta_hi = kNaN;
  int cells = 0, n = 0;  // cells inside, of n x n
  bool at_theta_lo = false, at_theta_hi = false, at_eta_lo = false, at_eta_hi = false;
  // Row j (eta index, from eta_lo) holds n characters, '1' inside; cell (i, j) sits
  // at theta_lo + i (theta_hi - theta_lo)/(n - 1) of the box, same for eta.
  std::vector<std::string> mask;
  bool contains(const Box& box, double theta, double eta) const;
};

struct FitOptions {
  int region_n = 161;      // fine grid over the box, per axis
  double delta = 5.99;     // misfit - min for 95% with 2 parameters (chi-square, 2 dof)
  double delta1 = 3.84;    // misfit - min for one parameter's 95% interval (chi-square, 1 dof)
  int global_evals = 3000; // GN_DIRECT_L evaluations
  double reach_sigmas = 2; // a target further than this many sigma beyond the surrogate's range is unreachable
};

struct FitResult {
  Box box;
  bool ok = false;  // false: some target is unreachable (see `unreachable`); theta, eta are no answer
  double theta = kNaN, eta = kNaN, misfit = kNaN;
  std::vector<TargetFit> targets;
  // Used in the misfit: r' C^-1 r with C_kk = sigma_k^2 and C_kl = rho_kl cos_kl
  // noise_k noise_l, cos_kl the cosine between the two surrogates' hat vectors at
  // the point. Empty, or every rho 0, and the misfit is the plain sum of squares.
  std::vector<PairCorrelation> correlations;
  Region region;
  // Each parameter's own 95% interval (the other one free): the cells with misfit -
  // min <= 3.84 (chi-square, 1 dof), projected. Narrower than the joint region's extents.
  double theta_lo1 = kNaN, theta_hi1 = kNaN, eta_lo1 = kNaN, eta_hi1 = kNaN;
  std::vector<std::string> warnings, unreachable;
  std::string method;
  nlohmann::json to_json() const;
};

// models[k] is the surrogate for targets[k]; `correlations` the replica correlations
// between pairs of targets (none: independent). Throws std::invalid_argument when
// the sizes disagree, the box is empty or a pair names no target.
FitResult invert(const std::vector<Model>& models, const std::vector<Target>& targets, const Box& box,
                 const FitOptions& options = {}, const std::vector<PairCorrelation>& correlations = {});

}  // namespace demcal::calibrate
