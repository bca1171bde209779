#pragma once
// Mohr-Coulomb envelopes from triaxial tests at several confining pressures:
// sigma1 = N sigma3 + 2 c sqrt(N), N = tan^2(45 deg + phi/2), by least squares,
// with standard errors; and the zero-cohesion line sigma1 = N0 sigma3. Each test
// gives sigma3, the confining pressure its servo held, and sigma1 from its stored
// angle, sigma1 = sigma3 (1 + sin phi) / (1 - sin phi): the peak's, the running
// mean's peak or the critical state's.
#include "db/store.hpp"
#include "jobs/query.hpp"

#include <string>
#include <vector>

namespace demcal::calibrate {

struct Envelope {
  int n = 0;                      // (sigma3, sigma1) pairs
  int dof = 0;                    // n - 2: what the errors with cohesion rest on
  int pressures = 0;              // distinct sigma3
  double phi_deg = 0, phi_se = 0; // with cohesion (NaN at one pressure; se NaN with fewer than 3 pairs)
  double c = 0, c_se = 0;         // cohesion, in the units of sigma (NaN at one pressure)
  double phi0_deg = 0, phi0_se = 0;  // zero cohesion
};

// With one distinct sigma3, only the zero-cohesion line (the tests' secant angle; phi
// and c NaN). Throws std::invalid_argument without tests, or for a slope N <= 1 (no
// positive friction angle).
Envelope fit_envelope(const std::vector<double>& sigma3, const std::vector<double>& sigma1);

// Which angle of each test the envelope is drawn through.
enum class EnvelopeState { peak, smoothed, cv };
const char* state_metric(EnvelopeState state);  // "phi_peak_deg", ...
// The two-sided 95% Student t quantile for `dof` degrees of freedom (1.96 beyond 30).
double t95(int dof);

struct PointEnvelope {
  double theta = 0, eta = 0;
  std::vector<double> sigma3_kpa, sigma1_kpa;
  Envelope env;
  std::string note;  // why no envelope (one pressure only, ...)
  // Tasks of the point without a peak: "10 kPa: task 5 failed: invalid in stage shear: ...".
  std::vector<std::string> left_out;
  int warned = 0;             // tests used whose task carries warnings
  std::string first_warning;  // the first of them, as the task stores it
  int spiked = 0;             // peaks used that rest on a spike (peak_on_a_spike)
  int not_critical = 0;       // critical states used from a window the run judged not at one
};

// Per (theta, eta) of the job: sigma3 = confining_kpa, sigma1 from the state's angle
// (kPa) of every finished task. Throws JobError for bad input (no job, no data, other
// parameters varying).
std::vector<PointEnvelope> job_envelopes(db::Store& store, const std::string& job, const std::vector<jobs::Where>& where,
                                         EnvelopeState state = EnvelopeState::peak);

}  // namespace demcal::calibrate
