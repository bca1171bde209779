#pragma once
// A smooth surrogate of one metric over (theta, eta): candidates are a thin-plate
// spline with a linear polynomial and a smoothing term, and quadratic and cubic
// least-squares polynomials; the one with the smallest leave-one-out (LOO) error
// wins, the spline's smoothing chosen the same way. See docs/calibration.md.
#include "response_surface.hpp"

#include <Eigen/Dense>
#include <string>
#include <vector>

namespace demcal::calibrate {

enum class SurrogateKind { thin_plate, quadratic, cubic };
std::string kind_name(SurrogateKind k);

struct SurrogateCandidate {
  SurrogateKind kind;
  double lambda = 0;   // thin-plate smoothing (0: interpolation)
  double loo_rms = 0;
};

class Surrogate {
 public:
  // Value at (theta in degrees, eta).
  double operator()(double theta, double eta) const;

  SurrogateKind kind() const { return kind_; }
  double lambda() const { return lambda_; }
  double loo_rms() const { return loo_rms_; }         // RMS of the LOO residuals, metric units
  double loo_max() const { return loo_max_; }         // largest |LOO residual|
  // Mean leverage (trace of the hat matrix / points, 1 for an interpolant): the
  // share of a point mean's noise variance the surface carries at the points.
  double mean_leverage() const { return leverage_; }
  int points() const { return static_cast<int>(u_.size()); }
  // The surface is linear in its points' means: s(theta, eta) = hat(theta, eta) . y.
  // How much each point's noise reaches a value; two surrogates over the same points
  // carry correlated noise in proportion to the cosine between their hat vectors.
  Eigen::VectorXd hat(double theta, double eta) const;
  bool same_points(const Surrogate& other) const { return u_ == other.u_ && v_ == other.v_; }
  const std::vector<SurrogateCandidate>& candidates() const { return candidates_; }
  // e.g. "thin-plate spline (lambda 1e-3), LOO RMS 0.21 deg over 30 points"; `unit` of the metric fitted
  std::string describe(const std::string& unit = "") const;

  friend Surrogate fit_surrogate(const std::vector<double>&, const std::vector<double>&, const std::vector<double>&,
                                 const std::vector<double>&, const Box&);

 private:
  double u(double theta) const { return (theta - box_.theta_lo) / (box_.theta_hi - box_.theta_lo); }
  double v(double eta) const { return (eta - box_.eta_lo) / (box_.eta_hi - box_.eta_lo); }

  SurrogateKind kind_ = SurrogateKind::thin_plate;
  double lambda_ = 0, loo_rms_ = 0, loo_max_ = 0, leverage_ = 1;
  Box box_;                        // normalisation: the box maps to the unit square
  std::vector<double> u_, v_;      // centres (normalised)
  Eigen::VectorXd w_, poly_;       // spline weights, polynomial coefficients
  Eigen::MatrixXd coef_map_;       // (w_, poly_) = coef_map_ * y for the thin-plate spline, poly_ = coef_map_ * y otherwise
  std::vector<SurrogateCandidate> candidates_;
};

// theta, eta, y (means) and weights (replica counts; relative) per point; box for
// normalisation. Throws std::invalid_argument when the points cannot carry a
// surface over two variables (fewer than 4 points, or all on one line).
Surrogate fit_surrogate(const std::vector<double>& theta, const std::vector<double>& eta, const std::vector<double>& y,
                        const std::vector<double>& weight, const Box& box);
// Over the points of a response surface that have data.
Surrogate fit_surrogate(const ResponseSurface& rs);

}  // namespace demcal::calibrate
