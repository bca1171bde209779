#include "envelope.hpp"
#include "excerpt.hpp"

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
double dphi_dN(double N) { return 1.0 / ((1 + N) * std::sqrt(N)) * 180 / kPi; }  // degrees per unit N

}  // namespace

Envelope fit_envelope(const std::vector<double>& s3, const std::vector<double>& s1) {
  if (s3.size() != s1.size()) throw std::invalid_argument("sigma3 and sigma1 differ in length");
  Envelope e;
  e.n = static_cast<int>(s3.size());
  e.pressures = static_cast<int>(std::set<double>(s3.begin(), s3.end()).size());
  if (e.pressures < 2) throw std::invalid_argument("an envelope needs at least two confining pressures");
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
  if (!(N > 0)) throw std::invalid_argument("the fitted slope sigma1/sigma3 is not positive: no friction angle");
  e.phi_deg = phi_of(N);
  e.phi_se = dphi_dN(N) * std::sqrt(varN);
  const double rN = std::sqrt(N);
  e.c = b / (2 * rN);
  const double dcdb = 1 / (2 * rN), dcdN = -b / (4 * N * rN);
  e.c_se = std::sqrt(dcdb * dcdb * varb + dcdN * dcdN * varN + 2 * dcdb * dcdN * covNb);
  // Through the origin.
  double sxx0 = 0, sxy0 = 0;
  for (int i = 0; i < e.n; ++i) sxx0 += s3[i] * s3[i], sxy0 += s3[i] * s1[i];
  const double N0 = sxy0 / sxx0;
  double rss0 = 0;
  for (int i = 0; i < e.n; ++i) rss0 += std::pow(s1[i] - N0 * s3[i], 2);
  e.phi0_deg = phi_of(N0);
  e.phi0_se = dphi_dN(N0) * std::sqrt(rss0 / (n - 1) / sxx0);
  return e;
}

std::vector<PointEnvelope> job_envelopes(db::Store& store, const std::string& job, const std::vector<jobs::Where>& where) {
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
    double q = NAN;
    for (const auto& m : r.metrics)
      if (m.first == "q_peak_pa") q = m.second;
    if (!std::isfinite(q)) {
      pe.left_out.push_back(why.str() + "has no q_peak_pa");
      continue;
    }
    if (!msg.warning.empty() && pe.warned++ == 0) pe.first_warning = msg.warning;
    pe.sigma3_kpa.push_back(s3);
    pe.sigma1_kpa.push_back(s3 + q / 1000.0);
    ++usable;
  }
  if (usable == 0) throw jobs::JobError("--job", "no data: no finished task of job \"" + job + "\" has q_peak_pa");
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
