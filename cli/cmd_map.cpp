// demcal map: a contour map of one metric over (theta, eta); demcal envelope:
// Mohr-Coulomb friction angle and cohesion across confining pressures.
#include "common.hpp"

#include "calibrate/calibration.hpp"
#include "calibrate/envelope.hpp"
#include "calibrate/excerpt.hpp"
#include "calibrate/map.hpp"
#include "calibrate/metric.hpp"
#include "db/store.hpp"
#include "jobs/job_error.hpp"
#include "jobs/query.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <iomanip>
#include <sstream>

namespace demcal::cli {

namespace {

struct MapArgs {
  std::string db = "demcal.db", job, metric, out, title;
  std::vector<std::string> where;
  bool no_fit = false;
};

// The grid points a map's reader should know of: holes, points short of replicas,
// peaks on a spike.
void print_map_points(const calibrate::ResponseSurface& rs) {
  for (const auto& p : rs.points)
    if (p.hole() && !p.refine)
      std::cout << "hole: theta = " << p.theta << ", eta = " << p.eta << " (" << p.without_value() << ")\n";
  for (const auto& p : rs.points)
    if (p.partial())
      std::cout << "short of replicas: theta = " << p.theta << ", eta = " << p.eta << " (the mean of " << p.n()
                << "; " << p.without_value() << ")\n";
  for (const auto& p : rs.points)
    if (p.spiked > 0)
      std::cout << "peak on a spike: theta = " << p.theta << ", eta = " << p.eta << " (" << p.spiked << " of "
                << p.n() << " replica(s))\n";
  if (rs.on_spike > 0)
    std::cout << "(phi_peak " << calibrate::spike_rule() << "; --metric phi_peak_smoothed_deg maps the running "
              << "mean's peak, " << calibrate::running_mean_vs_spike() << ")\n";
}

// Whether the latest fit was drawn, and why not when the job has fits on other pins.
void print_overlay_note(const std::optional<calibrate::MapOverlay>& overlay, int other_pins, const std::string& job,
                        const std::string& pins) {
  if (!overlay && other_pins > 0)
    std::cout << "no fit drawn: job " << job << "'s " << other_pins << " fit(s) were made on other --where pins "
              << "than this map's (" << (pins.empty() ? std::string("none") : pins)
              << "); a fit is drawn on the map of the pins it was made on\n";
  if (overlay)
    std::cout << "drawn: 95% region and best point of fit " << overlay->fit_id
              << (overlay->targets.empty() ? std::string() : " (targets " + overlay->targets + ")") << "\n";
}

int run_map(const MapArgs& a) {
  std::vector<jobs::Where> where;
  for (const auto& w : a.where) where.push_back(jobs::parse_where(w));
  const std::string out = a.out.empty() ? "map_" + a.metric + ".png" : a.out;
  require_writable_file("--out", out);
  require_db(a.db);
  db::Store store(a.db, /*read_only=*/true);
  const std::vector<std::string> jobs = a.job.empty() ? std::vector<std::string>{} : std::vector<std::string>{a.job};
  const std::string job = calibrate::job_for_metric(store, a.metric, jobs, where, "--metric");
  calibrate::GatherOptions go;
  go.where = where;
  const calibrate::ResponseSurface rs = calibrate::gather(store, job, a.metric, go);
  calibrate::Surrogate s;
  try {
    s = calibrate::fit_surrogate(rs);
  } catch (const std::invalid_argument& e) {
    throw jobs::JobError("--job", "job \"" + job + "\", " + a.metric + ": " + e.what());
  }
  std::optional<calibrate::MapOverlay> overlay;
  int other_pins = 0;
  if (!a.no_fit) overlay = calibrate::latest_fit_overlay(store, job, a.metric, where, &other_pins);
  std::string pins;
  for (const auto& w : where) pins += (pins.empty() ? "" : ", ") + w.key + "=" + w.value;
  calibrate::MapRequest mr;
  mr.out = out;
  mr.title = a.title;
  mr.pins = pins;
  mr.overlay = overlay ? &*overlay : nullptr;
  calibrate::draw_map(rs, s, mr);
  std::cout << "wrote " << out << ": " << rs.label << " of job " << job << (pins.empty() ? "" : " (" + pins + ")")
            << ", " << rs.with_data() << " point(s) with data, " << rs.holes() << " hole(s)"
            << (rs.partials() > 0 ? ", " + std::to_string(rs.partials()) + " short of replicas" : std::string()) << "\n"
            << "surrogate: " << s.describe(calibrate::metric_spec(rs.metric).unit) << "\n";
  print_map_points(rs);
  // What the surface stands on, as fit says it.
  const std::string hint = jobs::query_hint(a.db, job);
  for (const std::string& note : {rs.not_critical_note(hint), rs.warned_note(hint)})
    if (!note.empty()) std::cout << "warning: " << note << "\n";
  print_overlay_note(overlay, other_pins, job, pins);
  return kOk;
}

}  // namespace

void add_map(CLI::App& app, int& exit_code) {
  auto* cmd = app.add_subcommand("map", "Contour map of a metric over (theta, eta), PNG or SVG");
  auto a = std::make_shared<MapArgs>();
  cmd->add_option("--metric", a->metric, "phi_peak, phi_cv, phi_diff, repose, or a stored metric")->required()->check(kNonEmpty);
  cmd->add_option("--job", a->job, "job to draw (default: the job storing the metric)")->check(kNonEmpty);
  cmd->add_option("--where", a->where, "KEY=VALUE pinning a parameter other than theta and eta; repeatable");
  cmd->add_option("--db", a->db, "SQLite database")->check(kDbPath)->capture_default_str();
  cmd->add_option("--out", a->out, "output file, .png or .svg (default: map_METRIC.png)")->check(kPlainPath);
  cmd->add_option("--title", a->title, "the chart's title, one line (default: metric, job, points and holes, then the surrogate)")
      ->check(kOneLine)
      ->check(kNonEmpty);
  cmd->add_flag("--no-fit", a->no_fit, "do not draw the latest fit's 95% region");
  cmd->callback([a, &exit_code] {
    exit_code = guarded("", [&] { return chosen_job_errors(!a->job.empty(), [&] { return run_map(*a); }); });
  });
}

// What the table's numbers stand on: the tests left out and why, the results used
// that carry warnings (a fast shear's peaks, spikes, windows not at critical state),
// errors resting on one or two degrees of freedom, and a cohesion spheres cannot have,
// which such results make.
void print_envelope_caveats(const std::vector<calibrate::PointEnvelope>& envs, calibrate::EnvelopeState state,
                            const std::string& hint) {
  int warned = 0, used = 0, spiked = 0, not_critical = 0;
  std::string first;
  for (const auto& e : envs) {
    for (const auto& why : e.left_out)
      std::cout << "left out at theta " << e.theta << ", eta " << e.eta << ": " << why << "\n";
    if (!e.note.empty()) continue;  // no envelope: its results were not used
    used += static_cast<int>(e.sigma3_kpa.size());
    if (e.warned > 0 && warned == 0) first = e.first_warning;
    warned += e.warned;
    spiked += e.spiked;
    not_critical += e.not_critical;
  }
  const char* what = state == calibrate::EnvelopeState::cv ? "critical states" : "peaks";
  if (warned > 0)
    std::cout << "warning: " << warned << " of the " << used << " " << what << " used carry warnings (" << hint
              << "), e.g.: " << calibrate::first_warning(first) << "\n";
  if (spiked > 0)
    std::cout << "warning: " << spiked << " of the " << used << " peaks used rest on a spike of the walls' stress (phi_peak "
              << calibrate::spike_rule() << "): --state smoothed draws the envelope through the running mean's peaks\n";
  if (not_critical > 0)
    std::cout << "warning: " << not_critical << " of the " << used
              << " critical states used come from a window the run judged not at critical state (still changing volume "
                 "or phi_mob drifting)\n";
  const auto mean = [](const std::vector<double>& v) {
    double s = 0;
    for (double x : v) s += x;
    return v.empty() ? 0.0 : s / static_cast<double>(v.size());
  };
  for (const auto& e : envs) {
    if (!e.note.empty()) continue;
    // A standard error from one or two residuals: its 95% interval is Student's, not 2 se.
    // (On exact data the errors are round-off: nothing to widen.) The line with
    // cohesion first; without it, the zero-cohesion line's.
    const auto few_dof = [&](const char* which, int dof, int parameters) {
      std::cout << "warning: theta " << e.theta << ", eta " << e.eta << ": " << which << " on " << dof
                << " degree(s) of freedom (" << e.env.n << " tests, " << parameters << " parameter"
                << (parameters > 1 ? "s" : "") << "): a 95% interval is " << calibrate::t95(dof)
                << " standard errors either side, not 2 (replicas narrow it)\n";
    };
    if (e.env.dof >= 1 && e.env.dof <= 2 && e.env.phi_se > 1e-6)
      few_dof("the errors with cohesion rest", e.env.dof, 2);
    else if (e.env.n - 1 <= 2 && e.env.phi0_se > 1e-6)
      few_dof("the zero-cohesion angle's error rests", e.env.n - 1, 1);
    // Beyond the 95% interval and a fiftieth of the mean pressure (on exact data both c
    // and its error are round-off); with two tests, beyond a tenth of their mean. Either
    // sign: a negative intercept is a tension the grains cannot carry.
    const double bound = std::isfinite(e.env.c_se)
                             ? std::max(calibrate::t95(e.env.dof) * e.env.c_se, 0.02 * mean(e.sigma3_kpa))
                             : 0.1 * mean(e.sigma3_kpa);
    if (!(std::abs(e.env.c) > bound)) continue;
    std::ostringstream c;
    c << std::setprecision(3) << e.env.c;
    if (std::isfinite(e.env.c_se)) c << " +- " << e.env.c_se;
    std::cout << "warning: theta " << e.theta << ", eta " << e.eta << ": cohesion " << c.str()
              << " kPa from grains without cohesion: the straight line through the " << what
              << " has it from the envelope's "
              << (e.env.c > 0 ? "curvature (a dense sample's peak angle falls with pressure)"
                              : "slope (the angle rises with pressure here; a negative c is a tension)")
              << " or from results of a shear too fast or a sample too small (the warnings above); phi at c = 0 is the "
                 "other reading\n";
  }
}

void add_envelope(CLI::App& app, int& exit_code) {
  auto* cmd = app.add_subcommand("envelope", "Mohr-Coulomb friction angle and cohesion across confining pressures");
  struct Args {
    std::string db = "demcal.db", job;
    std::vector<std::string> where;
    std::string state = "peak";
  };
  auto a = std::make_shared<Args>();
  cmd->add_option("--job", a->job, "triaxial job spanning several confining_kpa (default: the only job)")->check(kNonEmpty);
  cmd->add_option("--state", a->state,
                  "the angle each test gives: peak (phi_peak_deg), smoothed (phi_peak_smoothed_deg, the running "
                  "mean's peak, which a spike barely moves) or cv (phi_cv_deg, the critical state)")
      ->check(CLI::IsMember({"peak", "smoothed", "cv"}))
      ->capture_default_str();
  cmd->add_option("--where", a->where, "KEY=VALUE pinning another parameter; repeatable");
  cmd->add_option("--db", a->db, "SQLite database")->check(kDbPath)->capture_default_str();
  cmd->callback([a, &exit_code] {
    exit_code = guarded("", [&] {
      std::vector<jobs::Where> where;
      for (const auto& w : a->where) where.push_back(jobs::parse_where(w));
      require_db(a->db);
      db::Store store(a->db, /*read_only=*/true);
      std::string job = a->job;
      if (job.empty()) {
        const auto all = calibrate::base_jobs(store);
        if (all.size() != 1)
          throw jobs::JobError("--job", all.empty() ? "no data: the database holds no jobs" : "the database holds several jobs; name one");
        job = all.front();
      }
      const calibrate::EnvelopeState state = a->state == "cv"         ? calibrate::EnvelopeState::cv
                                             : a->state == "smoothed" ? calibrate::EnvelopeState::smoothed
                                                                      : calibrate::EnvelopeState::peak;
      const auto envs = calibrate::job_envelopes(store, job, where, state);
      if (std::all_of(envs.begin(), envs.end(), [](const auto& e) { return !e.note.empty(); }))
        throw jobs::JobError("--job", "job \"" + job + "\" has no (theta, eta) with an envelope (" + envs.front().note + ")");
      std::printf("%8s %8s %4s %5s  %18s  %18s  %18s\n", "theta", "eta", "n", "p", "phi (deg)", "c (kPa)", "phi, c=0 (deg)");
      // Two tests fix a line exactly, one test the secant: no standard error (NaN), said as n/a.
      bool two_tests = false, one_pressure = false;
      auto se = [](double s) {
        char buf[16];
        if (std::isfinite(s))
          std::snprintf(buf, sizeof buf, "%-6.2g", s);
        else
          std::snprintf(buf, sizeof buf, "%-6s", "n/a");
        return std::string(buf);
      };
      for (const auto& e : envs) {
        if (!e.note.empty()) {
          std::printf("%8.4g %8.4g %4zu %5s  %s\n", e.theta, e.eta, e.sigma3_kpa.size(), "-", e.note.c_str());
          continue;
        }
        if (e.env.pressures < 2) {
          one_pressure = true;
          std::printf("%8.4g %8.4g %4d %5d  %18s  %18s  %8.3f +- %s\n", e.theta, e.eta, e.env.n, e.env.pressures,
                      "n/a (one pressure)", "n/a", e.env.phi0_deg, se(e.env.phi0_se).c_str());
          continue;
        }
        two_tests = two_tests || e.env.n == 2;
        std::printf("%8.4g %8.4g %4d %5d  %8.3f +- %s  %8.3g +- %s  %8.3f +- %s\n", e.theta, e.eta, e.env.n, e.env.pressures,
                    e.env.phi_deg, se(e.env.phi_se).c_str(), e.env.c, se(e.env.c_se).c_str(), e.env.phi0_deg,
                    se(e.env.phi0_se).c_str());
      }
      std::cout << "n: tests fitted, p: distinct confining pressures; sigma1 = N sigma3 + 2 c sqrt(N), "
                   "N = tan^2(45 + phi/2), least squares over the tests, each at sigma3 = its confining pressure and "
                   "sigma1 = sigma3 (1 + sin phi) / (1 - sin phi) from its "
                << calibrate::state_metric(state) << "; +- one standard error (n - 2 degrees of freedom; c = 0: n - 1)\n";
      if (two_tests)
        std::cout << "n/a: the line through two tests fits them exactly and has no standard error; it takes three\n";
      if (one_pressure)
        std::cout << "one pressure: a line with cohesion takes two; phi at c = 0 is then the tests' secant angle, "
                     "sin phi = (sigma1 - sigma3) / (sigma1 + sigma3), their mean stress ratio's (one test: no error)\n";
      print_envelope_caveats(envs, state, jobs::query_hint(a->db, job));
      return kOk;
    });
  });
}

}  // namespace demcal::cli
