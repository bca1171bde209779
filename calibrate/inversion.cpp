#include "inversion.hpp"

#include "chi_square.hpp"
#include "metric.hpp"

#include "jobs/decimal.hpp"
#include "jobs/job_error.hpp"

#include <Eigen/Dense>
#include <nlopt.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <regex>
#include <stdexcept>

namespace demcal::calibrate {
namespace {

// " deg" after a value of `metric` (its unit from its name), "" for a pure number.
std::string unit_suffix(const std::string& metric) {
  const std::string unit = metric_spec(metric).unit;
  return unit.empty() ? "" : " " + unit;
}

using jobs::JobError;

std::string g(double v, int digits = 4) {
  char b[40];
  std::snprintf(b, sizeof b, "%.*g", digits, v);
  return b;
}

// A fraction as a whole percentage: "100%", never "1e+02%".
std::string percent(double fraction) {
  char b[40];
  std::snprintf(b, sizeof b, "%.0f%%", 100.0 * fraction);
  return b;
}

bool parse_number(const std::string& s, double& out) { return jobs::parse_decimal(s, out) && std::isfinite(out); }

std::pair<std::string, std::string> split_pair(const std::string& text, const std::string& field, const char* what) {
  const auto eq = text.find('=');
  if (eq == std::string::npos || eq == 0 || eq + 1 == text.size())
    throw JobError(field, std::string("expected METRIC=") + what + " (e.g. phi_peak=" +
                              (std::string(what) == "SIGMA" ? "1.0" : "41.4") + "), got \"" + text + "\"");
  const std::string name = text.substr(0, eq);
  static const std::regex ok("[A-Za-z_][A-Za-z0-9_.]*");
  if (!std::regex_match(name, ok)) throw JobError(field, "\"" + name + "\" is not a metric name (in \"" + text + "\")");
  return {name, text.substr(eq + 1)};
}

// The misfit r' C^-1 r of predictions against targets. C_kk = sigma_k^2; for two
// metrics of one job C_kl = rho_kl cos_kl noise_k noise_l, where rho is the replica
// correlation and cos_kl the cosine between the two surrogates' hat vectors at the
// point (how far their noise comes from the same grid points alike). cos <= 1, and
// C is positive definite wherever the matrix of rho is (Schur product theorem).
// Without correlations: the plain sum of squares.
struct Misfit {
  const std::vector<Model>* models;
  std::vector<double> values, sigma, noise;
  std::vector<PairCorrelation> pairs;  // those counted (estimated, rho != 0)

  // The effective noise correlation of pair `pc` at (th, et).
  double effective_rho(const PairCorrelation& pc, double th, double et) const {
    const Eigen::VectorXd hk = (*models)[pc.k].surrogate.hat(th, et), hl = (*models)[pc.l].surrogate.hat(th, et);
    const double nk = hk.norm(), nl = hl.norm();
    return nk > 0 && nl > 0 ? pc.c.rho * hk.dot(hl) / (nk * nl) : 0.0;
  }
  double operator()(double th, double et, const double* predicted) const {
    const std::size_t K = values.size();
    if (pairs.empty()) {
      double m = 0;
      for (std::size_t k = 0; k < K; ++k) {
        const double r = (predicted[k] - values[k]) / sigma[k];
        m += r * r;
      }
      return m;
    }
    const auto n = static_cast<Eigen::Index>(K);
    Eigen::MatrixXd C = Eigen::MatrixXd::Zero(n, n);
    Eigen::VectorXd r(n);
    for (std::size_t k = 0; k < K; ++k) {
      const auto i = static_cast<Eigen::Index>(k);
      C(i, i) = sigma[k] * sigma[k];
      r(i) = predicted[k] - values[k];
    }
    for (const auto& pc : pairs) {
      const auto k = static_cast<Eigen::Index>(pc.k), l = static_cast<Eigen::Index>(pc.l);
      C(k, l) = C(l, k) = effective_rho(pc, th, et) * noise[pc.k] * noise[pc.l];
    }
    return r.dot(C.llt().solve(r));
  }
};

struct Objective {
  const Misfit* misfit;
  const Box* box;
  mutable std::vector<double> predicted;  // scratch: NLopt evaluates one point at a time
  double operator()(double th, double et) const {
    const auto& models = *misfit->models;
    predicted.resize(models.size());
    for (std::size_t k = 0; k < models.size(); ++k) predicted[k] = models[k].surrogate(th, et);
    return (*misfit)(th, et, predicted.data());
  }
  double unit(const std::vector<double>& x) const {
    return (*this)(box->theta_lo + x[0] * (box->theta_hi - box->theta_lo), box->eta_lo + x[1] * (box->eta_hi - box->eta_lo));
  }
};

double nlopt_objective(unsigned n, const double* x, double* grad, void* data) {
  (void)grad;
  const auto* o = static_cast<const Objective*>(data);
  return o->unit(std::vector<double>(x, x + n));
}

// Where a point sits relative to the box, in words.
std::string where(const Box& b, double th, double et) {
  const double tt = 1e-6 * (b.theta_hi - b.theta_lo), te = 1e-6 * (b.eta_hi - b.eta_lo);
  std::string s = "theta = " + g(th) + " deg";
  if (std::abs(th - b.theta_lo) <= tt) s += " (the theta lower bound)";
  if (std::abs(th - b.theta_hi) <= tt) s += " (the theta upper bound)";
  s += ", eta = " + g(et);
  if (std::abs(et - b.eta_lo) <= te) s += " (the eta lower bound)";
  if (std::abs(et - b.eta_hi) <= te) s += " (the eta upper bound)";
  return s;
}

}  // namespace

Target parse_target(const std::string& text, const std::string& field) {
  const auto [name, value] = split_pair(text, field, "VALUE");
  Target t;
  t.metric = name;
  if (!parse_number(value, t.value)) throw JobError(field, "value of " + name + " is not a finite number: \"" + value + "\"");
  // An angle no sample can show is a typo, not a target out of the grid's reach.
  static const char* const angles[] = {"phi_peak", "phi_cv", "repose", "phi_peak_deg", "phi_cv_deg", "repose_deg"};
  const bool angle = std::find(std::begin(angles), std::end(angles), name) != std::end(angles);
  if (angle && !(t.value >= 0.0 && t.value < 90.0))
    throw JobError(field, name + " is an angle in degrees: must lie in [0, 90), got " + value);
  if ((name == "phi_diff" || name == "phi_diff_deg") && !(std::abs(t.value) < 90.0))
    throw JobError(field, name + " is a difference of angles in degrees: must lie in (-90, 90), got " + value);
  return t;
}

void apply_sigma(std::vector<Target>& targets, const std::string& text) {
  const auto [name, value] = split_pair(text, "--sigma", "SIGMA");
  double s = 0;
  if (!parse_number(value, s) || !(s > 0))
    throw JobError("--sigma", "sigma of " + name + " must be a positive finite number, got \"" + value + "\"");
  // Its square enters the misfit: 1e200 became inf there and null in the JSON.
  if (s > 1e100) throw JobError("--sigma", "sigma of " + name + " must be at most 1e100 (no metric is that uncertain), got " + value);
  // Matched as --target matches names: phi_peak and phi_peak_deg are one metric.
  bool found = false;
  for (auto& t : targets) {
    if (stored_reading(t.metric) != stored_reading(name)) continue;
    // A second value would silently win over the first.
    if (!std::isnan(t.sigma)) throw JobError("--sigma", "metric \"" + t.metric + "\" given twice");
    t.sigma = s;
    found = true;
  }
  if (!found) throw JobError("--sigma", "no --target for metric \"" + name + "\"");
}

bool Region::contains(const Box& box, double theta, double eta) const {
  if (n < 2 || mask.empty()) return false;
  const double fi = (theta - box.theta_lo) / (box.theta_hi - box.theta_lo) * (n - 1);
  const double fj = (eta - box.eta_lo) / (box.eta_hi - box.eta_lo) * (n - 1);
  const long i = std::lround(fi), j = std::lround(fj);
  if (i < 0 || j < 0 || i >= n || j >= n) return false;
  return mask[static_cast<std::size_t>(j)][static_cast<std::size_t>(i)] == '1';
}

double surrogate_error(const Surrogate& s, double replica_se) {
  // A LOO residual is the error of a surface fitted without the point plus the noise
  // of the point's own mean (replica_se^2): that noise is not an error of the
  // surface at a target, so it comes off. What is left cannot be less than the
  // noise the surface itself carries from its points (mean leverage x se^2).
  const double loo2 = s.loo_rms() * s.loo_rms(), se2 = replica_se * replica_se;
  return std::sqrt(std::max(loo2 - se2, s.mean_leverage() * se2));
}

namespace {

// Which correlations the misfit counts. Those of surrogates over different grid
// points are not (their hat vectors do not pair up), and a set of three or more
// whose matrix of rho is not positive definite (pairwise estimates from different
// tasks need not be) is dropped, with a warning.
std::vector<PairCorrelation> counted_pairs(const std::vector<Model>& models, FitResult& res) {
  for (auto& pc : res.correlations)
    if (pc.c.estimated && !models[pc.k].surrogate.same_points(models[pc.l].surrogate)) {
      pc.c = {};
      pc.c.reason = "the two metrics have data at different grid points";
    }
  const auto K = static_cast<Eigen::Index>(models.size());
  Eigen::MatrixXd R = Eigen::MatrixXd::Identity(K, K);
  std::vector<PairCorrelation> counted;
  for (const auto& pc : res.correlations)
    if (pc.c.estimated && pc.c.rho != 0.0) {
      R(static_cast<Eigen::Index>(pc.k), static_cast<Eigen::Index>(pc.l)) = pc.c.rho;
      R(static_cast<Eigen::Index>(pc.l), static_cast<Eigen::Index>(pc.k)) = pc.c.rho;
      counted.push_back(pc);
    }
  if (Eigen::LLT<Eigen::MatrixXd>(R).info() != Eigen::Success) {
    res.warnings.push_back("the replica correlations between the targets are not consistent with each other "
                           "(their matrix is not positive definite): the targets are counted as independent");
    for (auto& pc : res.correlations)
      if (pc.c.estimated) pc.c = {}, pc.c.reason = "dropped: not consistent with the other pairs";
    counted.clear();
  }
  return counted;
}

// The box sampled n x n: cell (i, j) at (theta(i), eta(j)).
struct FineGrid {
  Box box;
  int n;
  double theta(int i) const { return box.theta_lo + (box.theta_hi - box.theta_lo) * i / (n - 1); }
  double eta(int j) const { return box.eta_lo + (box.eta_hi - box.eta_lo) * j / (n - 1); }
  std::size_t cells() const { return static_cast<std::size_t>(n * n); }
};

// Each target's surrogate over the box (its range, where that is reached) and its
// sigma, into res.targets. Returns the surrogates' values on the fine grid,
// val[k][j * n + i].
std::vector<std::vector<double>> describe_targets(const std::vector<Model>& models, const std::vector<Target>& targets,
                                                  const FineGrid& grid, FitResult& res) {
  const int n = grid.n;
  std::vector<std::vector<double>> val(targets.size(), std::vector<double>(grid.cells()));
  for (std::size_t k = 0; k < targets.size(); ++k) {
    TargetFit t;
    t.metric = targets[k].metric;
    t.job = models[k].job;
    t.target = targets[k].value;
    t.loo_rms = models[k].surrogate.loo_rms();
    t.replica_se = models[k].replica_se;
    t.lo = INFINITY;
    t.hi = -INFINITY;
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const double v = models[k].surrogate(grid.theta(i), grid.eta(j));
        val[k][static_cast<std::size_t>(j * n + i)] = v;
        if (v < t.lo) t.lo = v, t.theta_at_lo = grid.theta(i), t.eta_at_lo = grid.eta(j);
        if (v > t.hi) t.hi = v, t.theta_at_hi = grid.theta(i), t.eta_at_hi = grid.eta(j);
      }
    t.sigma_given = std::isfinite(targets[k].sigma);
    t.lab_sigma = t.sigma_given ? targets[k].sigma : 0.0;
    t.surrogate_sigma = surrogate_error(models[k].surrogate, t.replica_se);
    t.noise_sigma = std::sqrt(models[k].surrogate.mean_leverage()) * t.replica_se;
    // The target's own uncertainty and the surrogate's error are independent; floored
    // so a perfect fit of noise-free data cannot make the misfit infinitely sharp.
    t.sigma = std::hypot(t.lab_sigma, t.surrogate_sigma);
    t.sigma = std::max({t.sigma, 1e-3 * (t.hi - t.lo), 1e-9});
    res.targets.push_back(t);
  }
  return val;
}

// A target beyond the surrogate's range by more than reach_sigmas is unreachable
// whatever the optimiser says. Beyond it but within reach of its sigma, the fit goes
// on, and its answer is only where the grid's values end (a repose target 3.7 above
// the grid's highest angle, inside 2 sigma, read as matched): a warning.
void judge_reach(FitResult& res, const Box& box, const FitOptions& opt) {
  for (const auto& t : res.targets) {
    if (t.target > t.hi + opt.reach_sigmas * t.sigma)
      res.unreachable.push_back(t.metric + " = " + g(t.target) + " is above anything the grid reaches: at most " + g(t.hi) +
                                " (at " + where(box, t.theta_at_hi, t.eta_at_hi) + "; sigma " + g(t.sigma, 2) +
                                "); extend the grid beyond that bound");
    else if (t.target < t.lo - opt.reach_sigmas * t.sigma)
      res.unreachable.push_back(t.metric + " = " + g(t.target) + " is below anything the grid reaches: at least " + g(t.lo) +
                                " (at " + where(box, t.theta_at_lo, t.eta_at_lo) + "; sigma " + g(t.sigma, 2) +
                                "); extend the grid beyond that bound");
  }
  for (const auto& t : res.targets) {
    const bool above = t.target > t.hi, below = t.target < t.lo;
    if ((above || below) && std::abs(t.target - (above ? t.hi : t.lo)) <= opt.reach_sigmas * t.sigma)
      res.warnings.push_back(t.metric + " = " + g(t.target) + " is " + (above ? "above" : "below") +
                             " anything the grid reaches (" + (above ? "at most " : "at least ") +
                             g(above ? t.hi : t.lo) + unit_suffix(t.metric) + ", at " +
                             where(box, above ? t.theta_at_hi : t.theta_at_lo, above ? t.eta_at_hi : t.eta_at_lo) +
                             "), within " + g(opt.reach_sigmas) + " sigma (" + g(t.sigma, 2) +
                             "): the answer lies where the grid's values end, not where the target is met; extend "
                             "the grid beyond that bound");
  }
}

// The misfit at every cell of the fine grid, from the surrogates' values there.
std::vector<double> misfit_on_grid(const Misfit& misfit, const std::vector<std::vector<double>>& val, const FineGrid& grid) {
  std::vector<double> mis(grid.cells()), pred(val.size());
  for (std::size_t c = 0; c < mis.size(); ++c) {
    for (std::size_t k = 0; k < val.size(); ++k) pred[k] = val[k][c];
    mis[c] = misfit(grid.theta(static_cast<int>(c % grid.n)), grid.eta(static_cast<int>(c / grid.n)), pred.data());
  }
  return mis;
}

// Global search over the unit square, then a local polish from the best start. `x`
// comes in as the best grid cell and `f` as the misfit there; each optimiser's point
// replaces them only where it is no worse.
void minimise(const Objective& obj, int n, const FitOptions& opt, std::vector<double>& x, double& f) {
  try {
    nlopt::opt global(nlopt::GN_DIRECT_L, 2);
    global.set_lower_bounds({0.0, 0.0});
    global.set_upper_bounds({1.0, 1.0});
    global.set_min_objective(nlopt_objective, const_cast<Objective*>(&obj));
    global.set_maxeval(opt.global_evals);
    std::vector<double> xg = {0.5, 0.5};
    double fg = 0;
    global.optimize(xg, fg);
    if (fg < f) f = fg, x = xg;
  } catch (const std::exception&) {
    // DIRECT stopping on its own limits is not a failure; the grid start stands.
  }
  try {
    nlopt::opt local(nlopt::LN_BOBYQA, 2);
    local.set_lower_bounds({0.0, 0.0});
    local.set_upper_bounds({1.0, 1.0});
    local.set_min_objective(nlopt_objective, const_cast<Objective*>(&obj));
    local.set_xtol_abs(1e-9);
    local.set_maxeval(2000);
    local.set_initial_step(std::vector<double>{0.5 / (n - 1), 0.5 / (n - 1)});
    std::vector<double> xl = x;
    double fl = f;
    local.optimize(xl, fl);
    if (fl <= f) f = fl, x = xl;
  } catch (const std::exception&) {
  }
}

// The region: every fine-grid cell within delta of the minimum (at least the best
// point's cell), and each parameter's own interval: from the best point, every cell
// within delta1 (fewer than the region's, whose threshold is higher). Both extend to
// the cells' edges at the grid's resolution.
void trace_region(FitResult& res, const std::vector<double>& mis, const FineGrid& grid, const std::vector<double>& x,
                  const FitOptions& opt) {
  const int n = grid.n;
  const Box& box = grid.box;
  Region& R = res.region;
  R.n = n;
  R.mask.assign(static_cast<std::size_t>(n), std::string(static_cast<std::size_t>(n), '0'));
  R.theta_lo = R.eta_lo = INFINITY;
  R.theta_hi = R.eta_hi = -INFINITY;
  auto include = [&](int i, int j) {
    R.mask[static_cast<std::size_t>(j)][static_cast<std::size_t>(i)] = '1';
    ++R.cells;
    R.theta_lo = std::min(R.theta_lo, grid.theta(i));
    R.theta_hi = std::max(R.theta_hi, grid.theta(i));
    R.eta_lo = std::min(R.eta_lo, grid.eta(j));
    R.eta_hi = std::max(R.eta_hi, grid.eta(j));
    if (i == 0) R.at_theta_lo = true;
    if (i == n - 1) R.at_theta_hi = true;
    if (j == 0) R.at_eta_lo = true;
    if (j == n - 1) R.at_eta_hi = true;
  };
  res.theta_lo1 = res.theta_hi1 = res.theta;
  res.eta_lo1 = res.eta_hi1 = res.eta;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const double m = mis[static_cast<std::size_t>(j * n + i)];
      if (m <= res.misfit + opt.delta) include(i, j);
      if (m <= res.misfit + opt.delta1) {
        res.theta_lo1 = std::min(res.theta_lo1, grid.theta(i));
        res.theta_hi1 = std::max(res.theta_hi1, grid.theta(i));
        res.eta_lo1 = std::min(res.eta_lo1, grid.eta(j));
        res.eta_hi1 = std::max(res.eta_hi1, grid.eta(j));
      }
    }
  if (R.cells == 0) include(static_cast<int>(std::lround(x[0] * (n - 1))), static_cast<int>(std::lround(x[1] * (n - 1))));
  const double hc = 0.5 * (box.theta_hi - box.theta_lo) / (n - 1), he = 0.5 * (box.eta_hi - box.eta_lo) / (n - 1);
  auto to_edges = [](double& lo, double& hi, double half, double box_lo, double box_hi) {
    lo = std::max(box_lo, lo - half);
    hi = std::min(box_hi, hi + half);
  };
  to_edges(R.theta_lo, R.theta_hi, hc, box.theta_lo, box.theta_hi);
  to_edges(R.eta_lo, R.eta_hi, he, box.eta_lo, box.eta_hi);
  to_edges(res.theta_lo1, res.theta_hi1, hc, box.theta_lo, box.theta_hi);
  to_edges(res.eta_lo1, res.eta_hi1, he, box.eta_lo, box.eta_hi);
}

// A large residual at the best point (x, in the unit square): on a bound, the
// targets lie beyond it; with no more targets than unknowns, no point of the grid
// matches them together. (With more targets than unknowns a mismatch is reported as
// a warning by warn_identifiability.) Sets res.ok.
void judge_residuals(FitResult& res, const std::vector<double>& x, const FitOptions& opt) {
  const Box& box = res.box;
  const bool on_bound = x[0] < 1e-3 || x[0] > 1 - 1e-3 || x[1] < 1e-3 || x[1] > 1 - 1e-3;
  if (res.unreachable.empty() && (on_bound || res.targets.size() <= 2)) {
    for (const auto& t : res.targets)
      if (std::abs(t.residual) > opt.reach_sigmas * t.sigma)
        res.unreachable.push_back(
            (on_bound ? "the closest match lies on the edge of the grid, at " + where(box, res.theta, res.eta) +
                            ", and still misses "
                      : "no (theta, eta) inside the grid matches the targets together: the closest point, at " +
                            where(box, res.theta, res.eta) + ", misses ") +
            t.metric + " = " + g(t.target) + " by " + g(t.residual, 3) + " (" + g(std::abs(t.residual) / t.sigma, 2) +
            " sigma)" + (on_bound ? ": the targets lie beyond that bound; extend the grid" : ""));
  }
  res.ok = res.unreachable.empty();
}

// Warnings when the targets do not pin (theta, eta) down: too few targets, a region
// that fills or touches the grid's range or is elongated, a target flat along an axis
// near the answer, or more targets than unknowns that no point matches together.
void warn_identifiability(FitResult& res, const std::vector<Model>& models) {
  const Box& box = res.box;
  const Region& R = res.region;
  const std::size_t K = res.targets.size();
  const double wt = box.theta_hi - box.theta_lo, we = box.eta_hi - box.eta_lo;
  const double ft = (R.theta_hi - R.theta_lo) / wt, fe = (R.eta_hi - R.eta_lo) / we;
  if (K < 2)
    res.warnings.push_back("one target for two unknowns (theta, eta): the targets are matched along a curve, not at a point; "
                           "the best point is one of many (add a second target, e.g. phi_peak with phi_cv)");
  if (!res.ok) return;
  if (R.at_theta_lo && R.at_theta_hi)
    res.warnings.push_back("theta is not pinned down: the 95% region spans the whole theta range of the grid [" + g(box.theta_lo) +
                           ", " + g(box.theta_hi) + "] deg");
  else if (R.at_theta_lo || R.at_theta_hi)
    res.warnings.push_back("the 95% region reaches the theta " + std::string(R.at_theta_lo ? "lower" : "upper") + " bound (" +
                           g(R.at_theta_lo ? box.theta_lo : box.theta_hi) + " deg): the grid cuts it off; extend the grid there");
  if (R.at_eta_lo && R.at_eta_hi)
    res.warnings.push_back("eta is not pinned down: the 95% region spans the whole eta range of the grid [" + g(box.eta_lo) + ", " +
                           g(box.eta_hi) + "]");
  else if (R.at_eta_lo || R.at_eta_hi)
    res.warnings.push_back("the 95% region reaches the eta " + std::string(R.at_eta_lo ? "lower" : "upper") + " bound (" +
                           g(R.at_eta_lo ? box.eta_lo : box.eta_hi) + "): the grid cuts it off; extend the grid there");
  if (std::max(ft, fe) > 0.3 && std::max(ft, fe) > 4 * std::min(ft, fe))
    res.warnings.push_back(std::string("the 95% region is elongated along ") + (ft > fe ? "theta" : "eta") + " (" +
                           percent(ft) + " of the theta range, " + percent(fe) + " of the eta range): " +
                           (ft > fe ? "theta" : "eta") + " is poorly determined by these targets");
  // A target that barely changes across an axis near the answer cannot pin that axis.
  for (std::size_t k = 0; k < K; ++k) {
    const auto& s = models[k].surrogate;
    const double ht = 0.01 * wt, he2 = 0.01 * we;
    const double t0 = std::clamp(res.theta, box.theta_lo + ht, box.theta_hi - ht);
    const double e0 = std::clamp(res.eta, box.eta_lo + he2, box.eta_hi - he2);
    const double dth = (s(t0 + ht, e0) - s(t0 - ht, e0)) / (2 * ht) * wt * 0.25;
    const double det = (s(t0, e0 + he2) - s(t0, e0 - he2)) / (2 * he2) * we * 0.25;
    if (std::abs(dth) < res.targets[k].sigma)
      res.warnings.push_back(res.targets[k].metric + " is nearly flat in theta near the best point (changes by " + g(dth, 2) + unit_suffix(res.targets[k].metric) +
                             " over a quarter of the theta range, less than its sigma " + g(res.targets[k].sigma, 2) +
                             "): it cannot pin theta there");
    if (std::abs(det) < res.targets[k].sigma)
      res.warnings.push_back(res.targets[k].metric + " is nearly flat in eta near the best point (changes by " + g(det, 2) + unit_suffix(res.targets[k].metric) +
                             " over a quarter of the eta range, less than its sigma " + g(res.targets[k].sigma, 2) +
                             "): it cannot pin eta there");
  }
  // With more targets than unknowns the misfit at the best point is chi-square with
  // K - 2 dof; with two or fewer it is zero wherever the targets are reachable.
  const int dof = static_cast<int>(K) - 2;
  const double limit = dof >= 1 ? chi2_upper_quantile(dof, 0.01) : INFINITY;
  if (res.misfit > limit)
    res.warnings.push_back("the targets are not matched together: misfit " + g(res.misfit, 3) +
                           " at the best point (above the 99% chi-square level " + g(limit, 3) + " for " +
                           std::to_string(dof) + " dof); no (theta, eta) in the grid reproduces all of them");
}

}  // namespace

FitResult invert(const std::vector<Model>& models, const std::vector<Target>& targets, const Box& box,
                 const FitOptions& opt, const std::vector<PairCorrelation>& correlations) {
  if (models.size() != targets.size() || targets.empty())
    throw std::invalid_argument("invert: one model per target, at least one target");
  for (const auto& pc : correlations)
    if (!(pc.k < pc.l && pc.l < targets.size())) throw std::invalid_argument("invert: a correlation names no pair of targets");
  if (!(box.theta_hi > box.theta_lo) || !(box.eta_hi > box.eta_lo)) throw std::invalid_argument("invert: empty box");
  FitResult res;
  res.box = box;
  res.method = "surrogate + NLopt GN_DIRECT_L then LN_BOBYQA";
  const FineGrid grid{box, std::max(11, opt.region_n)};
  const int n = grid.n;
  const std::vector<std::vector<double>> val = describe_targets(models, targets, grid, res);
  judge_reach(res, box, opt);

  res.correlations = correlations;
  Misfit misfit{&models, {}, {}, {}, counted_pairs(models, res)};
  for (const auto& t : res.targets)
    misfit.values.push_back(t.target), misfit.sigma.push_back(t.sigma), misfit.noise.push_back(t.noise_sigma);
  const Objective obj{&misfit, &box, {}};
  const std::vector<double> mis = misfit_on_grid(misfit, val, grid);
  const auto best_cell = static_cast<std::size_t>(std::min_element(mis.begin(), mis.end()) - mis.begin());
  std::vector<double> x = {static_cast<double>(best_cell % n) / (n - 1), static_cast<double>(best_cell / n) / (n - 1)};
  double fbest = mis[best_cell];
  minimise(obj, n, opt, x, fbest);

  res.theta = box.theta_lo + x[0] * (box.theta_hi - box.theta_lo);
  res.eta = box.eta_lo + x[1] * (box.eta_hi - box.eta_lo);
  res.misfit = fbest;
  for (std::size_t k = 0; k < res.targets.size(); ++k) {
    res.targets[k].predicted = models[k].surrogate(res.theta, res.eta);
    res.targets[k].residual = res.targets[k].predicted - res.targets[k].target;
  }
  for (auto& pc : res.correlations)
    if (pc.c.estimated && !misfit.pairs.empty()) pc.at_best = misfit.effective_rho(pc, res.theta, res.eta);
  trace_region(res, mis, grid, x, opt);
  judge_residuals(res, x, opt);
  warn_identifiability(res, models);
  return res;
}

nlohmann::json FitResult::to_json() const {
  auto num = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); };
  nlohmann::json j;
  j["status"] = ok ? "ok" : "unreachable";
  j["box"] = {{"theta_lo", box.theta_lo}, {"theta_hi", box.theta_hi}, {"eta_lo", box.eta_lo}, {"eta_hi", box.eta_hi}};
  if (ok) {
    j["theta_deg"] = num(theta);
    j["eta"] = num(eta);
  } else {
    // Kept for the record, never as an answer.
    j["closest_theta_deg"] = num(theta);
    j["closest_eta"] = num(eta);
  }
  j["misfit"] = num(misfit);
  j["targets"] = nlohmann::json::array();
  for (const auto& t : targets)
    j["targets"].push_back({{"metric", t.metric}, {"job", t.job}, {"target", num(t.target)}, {"sigma", num(t.sigma)},
                            {"sigma_given", t.sigma_given}, {"lab_sigma", num(t.lab_sigma)}, {"surrogate_sigma", num(t.surrogate_sigma)}, {"noise_sigma", num(t.noise_sigma)}, {"predicted", num(t.predicted)}, {"residual", num(t.residual)},
                            {"loo_rms", num(t.loo_rms)}, {"replica_se", num(t.replica_se)}, {"range", {num(t.lo), num(t.hi)}}});
  j["correlations"] = nlohmann::json::array();
  for (const auto& pc : correlations)
    j["correlations"].push_back({{"metrics", {targets[pc.k].metric, targets[pc.l].metric}},
                                 {"rho", pc.c.rho},
                                 {"dof", pc.c.dof},
                                 {"points", pc.c.points},
                                 {"estimated", pc.c.estimated},
                                 {"at_best", num(pc.at_best)},
                                 {"reason", pc.c.reason}});
  j["region"] = {{"level", "misfit - min <= 5.99 (95%, 2 parameters)"},
                 {"theta_deg", {num(region.theta_lo), num(region.theta_hi)}},
                 {"eta", {num(region.eta_lo), num(region.eta_hi)}},
                 {"cells", region.cells},
                 {"n", region.n},
                 {"mask", region.mask}};
  j["intervals"] = {{"level", "misfit - min <= 3.84 (95%, each parameter alone)"},
                    {"theta_deg", {num(theta_lo1), num(theta_hi1)}},
                    {"eta", {num(eta_lo1), num(eta_hi1)}}};
  j["warnings"] = warnings;
  j["unreachable"] = unreachable;
  j["method"] = method;
  return j;
}

}  // namespace demcal::calibrate
