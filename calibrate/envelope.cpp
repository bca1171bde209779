#include "envelope.hpp"
#include "excerpt.hpp"
#include "metric.hpp"

#include "response_surface.hpp"
#include "jobs/job_error.hpp"

#include <cmath>
#include <map>
#include <sstream>
#include <set>
#include <stdexcept>

namespace demcal::calibrate {
namespace {

constexpr double kPi = 3.14159265358979323846;

double phi_of(double N) { return (2 * std::atan(std::sqrt(N)) - kPi / 2) * 180 / kPi; }
double N_of(double phi_deg) {
  const double s = std::sin(phi_deg * kPi / 180);
  return (1 + s) / (1 - s);
}
double dphi_dN(double N) { return 1.0 / ((1 + N) * std::sqrt(N)) * 180 / kPi; }  // degrees per unit N

}  // namespace

const char* state_metric(EnvelopeState state) {
  switch (state) {
    case EnvelopeState::smoothed: return "phi_peak_smoothed_deg";
    case EnvelopeState::cv: return "phi_cv_deg";
    default: return "phi_peak_deg";
  }
}

double t95(int dof) {
  static const double table[] = {NAN,   12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228,
                                 2.201, 2.179,  2.160, 2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086};
  if (dof < 1) return NAN;
  if (dof <= 20) return table[dof];
  return dof <= 30 ? 2.042 : 1.96;
}

namespace {

// The zero-cohesion line sigma1 = N0 sigma3 through the origin, into e.phi0_*.
void fit_through_origin(const std::vector<double>& s3, const std::vector<double>& s1, Envelope& e) {
  double sxx0 = 0, sxy0 = 0;
  for (int i = 0; i < e.n; ++i) sxx0 += s3[i] * s3[i], sxy0 += s3[i] * s1[i];
  const double N0 = sxy0 / sxx0;
  if (!(N0 > 1)) throw std::invalid_argument("sigma1/sigma3 is not above 1: no positive friction angle");
  double rss0 = 0;
  for (int i = 0; i < e.n; ++i) rss0 += std::pow(s1[i] - N0 * s3[i], 2);
  e.phi0_deg = phi_of(N0);
  e.phi0_se = e.n > 1 ? dphi_dN(N0) * std::sqrt(rss0 / (e.n - 1) / sxx0) : NAN;
}

}  // namespace

Envelope fit_envelope(const std::vector<double>& s3, const std::vector<double>& s1) {
  if (s3.size() != s1.size()) throw std::invalid_argument("sigma3 and sigma1 differ in length");
  if (s3.empty()) throw std::invalid_argument("no tests");
  Envelope e;
  e.n = static_cast<int>(s3.size());
  e.dof = e.n - 2;
  e.pressures = static_cast<int>(std::set<double>(s3.begin(), s3.end()).size());
  fit_through_origin(s3, s1, e);
  if (e.pressures < 2) {  // one pressure: the secant angle only; a line with cohesion needs two
    e.phi_deg = e.phi_se = e.c = e.c_se = NAN;
    return e;
  }
  const double n = e.n;
  double mx = 0, my = 0;
  for (int i = 0; i < e.n; ++i) mx += s3[i], my += s1[i];
  mx /= n;
  my /= n;
  double sxx = 0, sxy = 0;
  for (int i = 0; i < e.n; ++i) sxx += (s3[i] - mx) * (s3[i] - mx), sxy += (s3[i] - mx) * (s1[i] - my);
  const double N = sxy / sxx, b = my - N * mx;
  double rss = 0;
  for (int i = 0; i < e.n; ++i) rss += std::pow(s1[i] - (N * s3[i] + b), 2);
  const double s2 = e.n > 2 ? rss / (n - 2) : NAN;
  const double varN = s2 / sxx, varb = s2 * (1 / n + mx * mx / sxx), covNb = -mx * s2 / sxx;
  // N = 1 is phi = 0; below it sigma1 would fall behind sigma3 as the pressure rises.
  if (!(N > 1)) throw std::invalid_argument("the fitted slope sigma1/sigma3 is not above 1: no positive friction angle");
  e.phi_deg = phi_of(N);
  e.phi_se = dphi_dN(N) * std::sqrt(varN);
  const double rN = std::sqrt(N);
  e.c = b / (2 * rN);
  const double dcdb = 1 / (2 * rN), dcdN = -b / (4 * N * rN);
  e.c_se = std::sqrt(dcdb * dcdb * varb + dcdN * dcdN * varN + 2 * dcdb * dcdN * covNb);
  return e;
}

std::vector<PointEnvelope> job_envelopes(db::Store& store, const std::string& job, const std::vector<jobs::Where>& where,
                                         EnvelopeState state) {
  const std::string metric = state_metric(state);
  if (!store.find_job(job)) throw jobs::JobError("--job", "no job named \"" + job + "\"");
  const auto rows = jobs::select_rows(store, job, where);
  if (rows.empty()) throw jobs::JobError("--where", "no task of job \"" + job + "\" matches the filters");
  // The wrong kind of job is the first thing to say, before asking to pin a parameter.
  for (const auto& r : rows)
    if (!r.params.contains("confining_kpa") || !r.params.contains("theta_deg") || !r.params.contains("eta"))
      throw jobs::JobError("--job", "job \"" + job + "\" has no confining_kpa, theta_deg and eta parameters (scene " + r.task.scene +
                                        "); an envelope needs triaxial tasks");
  // Pinned, it would leave one pressure and read "needs at least two".
  for (const auto& w : where)
    if (w.key == "confining_kpa")
      throw jobs::JobError("--where", "confining_kpa is the envelope's axis: it is fitted across the confining "
                                      "pressures, so it cannot be pinned");
  std::map<std::string, std::set<std::string>> seen;
  for (const auto& r : rows)
    for (const auto& [k, v] : r.params.items())
      if (k != "seed" && k != "theta_deg" && k != "eta" && k != "confining_kpa") seen[k].insert(v.dump());
  for (const auto& [k, vals] : seen)
    if (vals.size() > 1)
      throw jobs::JobError("--where", "job \"" + job + "\" varies " + k + " besides theta_deg, eta and confining_kpa; pick one with --where " + k + "=VALUE");
  std::map<std::pair<double, double>, PointEnvelope> by;
  int usable = 0;
  for (const auto& r : rows) {
    const double th = r.params["theta_deg"].get<double>(), et = r.params["eta"].get<double>();
    auto& pe = by[{th, et}];
    pe.theta = th;
    pe.eta = et;
    const double s3 = r.params["confining_kpa"].get<double>();
    const db::TaskMessage msg = db::task_message(r.task);
    std::ostringstream why;
    why << s3 << " kPa: task " << r.task.id << " ";
    if (r.task.status != "done") {
      why << (r.task.status == "failed" ? "failed: " + cut_at_word(msg.error, 160) : "not finished (" + r.task.status + ")");
      pe.left_out.push_back(why.str());
      continue;
    }
    double phi = NAN;
    for (const auto& m : r.metrics)
      if (m.first == metric) phi = m.second;
    // The servo holds sigma3 at the confining pressure (to ~1%); the angle is the walls'
    // measured stress ratio. sigma3 + q at the nominal pressure mixed the two (0.4 deg
    // off the task's own phi_peak where sigma3 had sagged by 2% at the peak).
    if (!std::isfinite(phi) || !(phi > -90.0 && phi < 90.0)) {
      pe.left_out.push_back(why.str() + "has no " + metric);
      continue;
    }
    if (!msg.warning.empty() && pe.warned++ == 0) pe.first_warning = msg.warning;
    if (state == EnvelopeState::peak && peak_on_a_spike(r.metrics)) ++pe.spiked;
    if (state == EnvelopeState::cv && says_not_at_critical_state(msg.warning)) ++pe.not_critical;
    pe.sigma3_kpa.push_back(s3);
    pe.sigma1_kpa.push_back(s3 * N_of(phi));
    ++usable;
  }
  if (usable == 0) throw jobs::JobError("--job", "no data: no finished task of job \"" + job + "\" has " + metric);
  std::vector<PointEnvelope> out;
  for (auto& [k, pe] : by) {
    try {
      pe.env = fit_envelope(pe.sigma3_kpa, pe.sigma1_kpa);
    } catch (const std::invalid_argument& e) {
      pe.note = e.what();
    }
    out.push_back(std::move(pe));
  }
  return out;
}

}  // namespace demcal::calibrate
