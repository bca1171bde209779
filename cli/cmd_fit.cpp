// demcal fit: invert target angles into (theta, eta) through surrogates of the
// stored response surfaces; optionally refine with DEM runs around the answer.
#include "common.hpp"

#include "calibrate/calibration.hpp"
#include "db/store.hpp"
#include "jobs/job_error.hpp"

#include <cmath>
#include <cstdio>
#include <iostream>

namespace demcal::cli {
namespace {

std::string g(double v, int digits = 4) {
  if (!std::isfinite(v)) return "-";
  char b[40];
  std::snprintf(b, sizeof b, "%.*g", digits, v);
  return b;
}

// What the sigma is made of: the surrogate's error, and the target's own when given.
std::string sigma_note(const calibrate::TargetFit& t) {
  if (!t.sigma_given) return "  (sigma: surrogate error)";
  return "  (sigma: " + g(t.lab_sigma, 3) + " given (+) " + g(t.surrogate_sigma, 3) + " surrogate error)";
}

void print_fit(std::ostream& out, const calibrate::Calibration& cal, std::int64_t fit_id) {
  const auto& r = cal.result;
  out << "fit " << (fit_id < 0 ? std::string("(not stored)") : std::to_string(fit_id)) << " (" << r.method << ")\n";
  out << "box: theta " << g(r.box.theta_lo) << " .. " << g(r.box.theta_hi) << " deg, eta " << g(r.box.eta_lo) << " .. "
      << g(r.box.eta_hi) << "\n";
  out << "surrogates:\n";
  for (std::size_t k = 0; k < cal.models.size(); ++k) {
    const auto& m = cal.models[k];
    const int partial = cal.surfaces[k].partials();
    out << "  " << m.metric << " (job " << m.job << "): " << m.surrogate.describe(calibrate::metric_spec(m.metric).unit) << ", " << cal.surfaces[k].holes()
        << " hole(s), " << (partial > 0 ? std::to_string(partial) + " point(s) short of replicas, " : std::string())
        << "replica se "
        << (m.replica_se > 0 ? g(m.replica_se, 3) : std::string("unknown (one replica a point: LOO alone measures the noise)"))
        << "\n";
  }
  for (const auto& pc : r.correlations) {
    out << "  replica correlation " << r.targets[pc.k].metric << " ~ " << r.targets[pc.l].metric << ": ";
    if (pc.c.estimated)
      out << g(pc.c.rho, 2) << " (" << pc.c.dof << " dof over " << pc.c.points << " points), counted in the misfit"
          << (std::isfinite(pc.at_best) ? " (" + g(pc.at_best, 2) + " between the two surrogates at the best point)" : "")
          << "\n";
    else
      out << "not estimated (" << pc.c.reason << "): counted as 0\n";
  }
  if (r.ok) {
    out << "best: theta = " << g(r.theta) << " deg, eta = " << g(r.eta) << " (misfit " << g(r.misfit, 3) << ")\n";
  } else {
    out << "best: none (a target is out of reach; see below)\n";
  }
  char line[200];
  std::snprintf(line, sizeof line, "  %-12s %10s %8s %10s %10s\n", "metric", "target", "sigma", "predicted", "residual");
  out << line;
  for (const auto& t : r.targets) {
    std::snprintf(line, sizeof line, "  %-12s %10s %8s %10s %10s%s\n", t.metric.c_str(), g(t.target).c_str(),
                  g(t.sigma, 3).c_str(), r.ok ? g(t.predicted).c_str() : "-", r.ok ? g(t.residual, 3).c_str() : "-",
                  sigma_note(t).c_str());
    out << line;
  }
  if (r.ok)
    out << "95% region (misfit - min <= 5.99): theta " << g(r.region.theta_lo) << " .. " << g(r.region.theta_hi) << " deg, eta "
        << g(r.region.eta_lo) << " .. " << g(r.region.eta_hi) << " (joint)\n"
        << "95% intervals, each parameter alone (misfit - min <= 3.84): theta " << g(r.theta_lo1) << " .. "
        << g(r.theta_hi1) << " deg, eta " << g(r.eta_lo1) << " .. " << g(r.eta_hi1) << "\n";
  for (const auto& w : r.warnings) out << "warning: " << w << "\n";
  for (const auto& u : r.unreachable) out << "unreachable: " << u << "\n";
}

struct FitArgs {
  std::string db = "demcal.db", out, format = "text";
  std::vector<std::string> targets, sigmas, jobs, where;
  int refine = 0, workers = 0;
};

calibrate::FitRequest fit_request(const FitArgs& a) {
  if (a.format != "text" && a.format != "json")
    throw jobs::JobError("--format", "expected text or json, got \"" + a.format + "\"");
  calibrate::FitRequest req;
  for (const auto& t : a.targets) req.targets.push_back(calibrate::parse_target(t));
  for (const auto& s : a.sigmas) calibrate::apply_sigma(req.targets, s);
  for (const auto& w : a.where) req.where.push_back(jobs::parse_where(w));
  req.jobs = a.jobs;
  return req;
}

std::vector<calibrate::RefineRound> refine_fit(db::Store& store, const calibrate::FitRequest& req,
                                               calibrate::Calibration& cal, const FitArgs& a,
                                               const std::string& out_dir) {
  if (a.refine <= 0 || !cal.result.ok) return {};
  calibrate::RefineOptions ro;
  ro.rounds = a.refine;
  ro.log = &std::cerr;
  ro.run_points = calibrate::dem_point_runner(out_dir, a.workers, &std::cerr, req.where);
  ro.resume_round = calibrate::dem_round_resumer(out_dir, a.workers, &std::cerr);
  return calibrate::refine(store, req, cal, ro);
}

void print_rounds(std::ostream& out, const std::vector<calibrate::RefineRound>& rounds, bool unsettled,
                  double tolerance) {
  for (const auto& r : rounds)
    out << "refine round " << r.round << ": "
        << (r.resumed ? std::string("resumed") : std::to_string(r.points.size()) + " run(s)")
        << "; candidate theta = " << g(r.theta) << ", eta = " << g(r.eta)
        << (std::isfinite(r.move) ? "; moved " + g(100 * r.move, 3) + "% of the range" : std::string("; no answer"))
        << " (fit " << r.fit_id << ")\n";
  if (unsettled)
    out << "warning: the refinement stopped after its " << rounds.size()
        << " round(s) with the candidate still moving (" << g(100 * rounds.back().move, 3)
        << "% of the range in the last round; under " << g(100 * tolerance, 3)
        << "% counts as settled): the answer is not settled yet; run more rounds (--refine N)\n";
}

int run_fit(const FitArgs& a) {
  const calibrate::FitRequest req = fit_request(a);
  require_db(a.db);
  // Opened read-only first: a foreign, newer or empty file is reported before
  // the read-write open would give it a schema.
  const std::string out_dir = a.out.empty() ? default_out_dir(a.db) : a.out;
  if (a.refine > 0) require_writable_dir(out_flag(a.out), out_dir);
  { db::Store probe(a.db, /*read_only=*/true); }
  // A database demcal may not write still answers: the fit is printed, not stored.
  const std::string refusal = db::write_refusal(a.db);
  if (!refusal.empty() && a.refine > 0)
    throw jobs::JobError("--refine", "stores its runs in " + a.db + ", which cannot be written: " + refusal);
  db::Store store(a.db, /*read_only=*/!refusal.empty());
  calibrate::Calibration cal = calibrate::calibrate(store, req);
  std::int64_t id = refusal.empty() ? calibrate::store_fit(store, req, cal, 0) : -1;
  if (id < 0) std::cerr << "demcal: warning: the fit is not stored: " << a.db << " cannot be written (" << refusal << ")\n";
  const std::vector<calibrate::RefineRound> rounds = refine_fit(store, req, cal, a, out_dir);
  if (!rounds.empty()) id = rounds.back().fit_id;
  // Rounds that ended because none were left, the candidate still moving: the
  // answer is not settled, whatever its region says.
  const double tolerance = calibrate::RefineOptions{}.tolerance;
  const bool unsettled = !rounds.empty() && rounds.back().ok && !(rounds.back().move < tolerance);
  if (a.format == "json") {
    nlohmann::json j =
        id < 0 ? calibrate::fit_record(req, cal, 0).result : nlohmann::json::parse(store.fits().back().result_json);
    j["fit_id"] = id < 0 ? nlohmann::json(nullptr) : nlohmann::json(id);
    if (!rounds.empty()) j["refine_converged"] = !unsettled;
    std::cout << j.dump(2) << "\n";
  } else {
    print_fit(std::cout, cal, id);
    print_rounds(std::cout, rounds, unsettled, tolerance);
  }
  if (!cal.result.ok) {
    std::cerr << "demcal: error: target out of reach of the grid: " << cal.result.unreachable.front() << "\n";
    return kRuntime;
  }
  return kOk;
}

}  // namespace

void add_fit(CLI::App& app, int& exit_code) {
  auto* cmd = app.add_subcommand("fit", "Invert target angles into (theta, eta) from the stored grid results");
  auto a = std::make_shared<FitArgs>();
  cmd->add_option("--target", a->targets, "METRIC=VALUE (phi_peak, phi_cv, phi_diff, repose, or a stored metric); repeatable")
      ->required();
  cmd->add_option("--sigma", a->sigmas, "METRIC=SIGMA: the target's own uncertainty (e.g. the laboratory's), added in quadrature to the surrogate's error (default: 0, an exact target)");
  cmd->add_option("--job", a->jobs, "job(s) to read (default: the job storing each metric); repeatable")->check(kNonEmpty);
  cmd->add_option("--where", a->where, "KEY=VALUE pinning a parameter other than theta and eta; repeatable");
  cmd->add_option("--db", a->db, "SQLite database")->check(kDbPath)->capture_default_str();
  cmd->add_option("--refine", a->refine, "rounds of DEM runs around the answer, refitting after each")->transform(kWholeNumber)->check(CLI::Range(0, 20));
  cmd->add_option("--workers", a->workers, "worker processes for --refine (default: the core count)")->transform(kWholeNumber)->check(CLI::Range(1, 4096));
  cmd->add_option("--out", a->out, "HDF5 output directory for --refine (default: demcal-out next to the database)")->check(kPlainPath);
  cmd->add_option("--format", a->format, "text or json")->capture_default_str();
  cmd->callback([a, &exit_code] {
    exit_code = guarded("", [&] { return chosen_job_errors(!a->jobs.empty(), [&] { return run_fit(*a); }); });
  });
}

}  // namespace demcal::cli
