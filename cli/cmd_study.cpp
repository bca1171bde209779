// demcal study timestep|grazing|fidelity|repose-fidelity: speed-against-accuracy studies (issue 9).
#include "common.hpp"

#include "db/schema.hpp"
#include "db/store.hpp"
#include "jobs/folder_lock.hpp"
#include "jobs/gnuplot_process.hpp"
#include "jobs/job_error.hpp"
#include "jobs/runner.hpp"
#include "calibrate/metric.hpp"
#include "calibrate/study.hpp"

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <stdexcept>
#include <iostream>
#include <memory>
#include <unistd.h>

namespace demcal::cli {
namespace fs = std::filesystem;
namespace {

struct StudyArgs {
  std::string name, db = "demcal.db", out;
  bool db_given = false;
  bool peak_given = false;  // even as raw: the other studies have no peak to judge
  bool quick = false;
  int workers = 0;
  double tolerance = 0.0;
  int replicas = 0;
  std::vector<std::string> knobs, references;
  std::string peak = "raw";
};

bool is_fidelity(const std::string& name) { return name == "fidelity" || name == "repose-fidelity"; }

// "particles=2000" -> {particles, 2000}
std::pair<std::string, double> parse_reference(const std::string& text) {
  const auto eq = text.find('=');
  if (eq == std::string::npos || eq == 0 || eq + 1 == text.size())
    throw jobs::JobError("--reference", "expected KNOB=VALUE (e.g. particles=2000), got \"" + text + "\"");
  try {
    std::size_t used = 0;
    const double v = std::stod(text.substr(eq + 1), &used);
    if (used != text.size() - eq - 1) throw std::invalid_argument("trailing");
    return {text.substr(0, eq), v};
  } catch (const std::logic_error&) {
    throw jobs::JobError("--reference", "not a number in \"" + text + "\"");
  }
}

int fidelity(const StudyArgs& a, const calibrate::StudyOptions& o) {
  db::Store store(a.db);
  const calibrate::FidelityStudy s = calibrate::run_fidelity_study(store, a.name, o);
  std::cout << "study " << s.name << " (" << s.scene << "), baseline " << s.baseline << "; " << s.replicas
            << " replica(s) per setting"
            << (o.smoothed_peak ? "; phi_peak judged by the peak of its running mean (phi_peak_smoothed_deg)" : "")
            << "\n";
  for (const auto& f : s.job_files) std::cout << "job file " << f << "\n";
  std::cout << s.tasks << " tasks in " << a.db << " (" << s.reused << " reused, " << s.ran << " run now)\n";
  for (const auto& k : s.knobs) {
    std::cout << "\n" << k.name << " (" << k.param << "):\n";
    std::string head = "  setting        ok/n   wall_s  Mpart-steps";
    for (const auto& m : s.metrics) head += "  " + std::string(m.size() < 14 ? 14 - m.size() : 0, ' ') + m + " (err +/- sd)";
    std::cout << head << "\n";
    for (const auto& p : k.points) {
      char line[160];
      std::snprintf(line, sizeof line, "  %-12s  %2d/%-2d  %7.3g  %11.4g", (p.label + (p.reference ? "*" : "")).c_str(),
                    p.replicas - p.failed, p.replicas, p.wall_s, p.work / 1e6);
      std::cout << line;
      for (std::size_t m = 0; m < s.metrics.size(); ++m) {
        std::snprintf(line, sizeof line, "  %7.2f (%5.2f +/- %4.2f)", p.mean[m], p.error[m], p.sd[m]);
        std::cout << line;
      }
      std::cout << (p.pareto ? "  pareto" : "") << (p.recommended ? "  recommended" : "")
                << (p.failed > 0 ? "  FAILED " + std::to_string(p.failed) : "")
                << (p.spikes.empty() ? "" : "  spike " + std::to_string(p.spikes.size())) << "\n";
    }
    std::cout << "  " << k.recommendation << "\n";
  }
  std::cout << "(* the reference setting; error = |mean - reference mean|, sd over replicas; cost for \"cheapest\" "
               "and the Pareto front: particle-steps, mean over replicas)\n";
  if (!s.failures.empty()) {
    std::cout << "failed tasks (" << s.failures.size() << "):\n";
    for (const auto& f : s.failures) std::cout << "  " << f << "\n";
  }
  if (!s.spikes.empty()) {
    std::cout << calibrate::spike_heading() << " (" << s.spikes.size() << "):\n";
    for (const auto& f : s.spikes) std::cout << "  " << f << "\n";
  }
  if (!s.warnings_note.empty()) std::cout << s.warnings_note << "\n";
  std::cout << s.recommendation << "\n";
  for (const auto& f : s.files) std::cout << "wrote " << f << "\n";
  // No knob could be judged (its reference failed, or every other setting did): the
  // study has no answer, which a script must see.
  if (!s.any_judged()) {
    std::cerr << "demcal: study " << s.name << ": no knob could be judged against its reference (the lines above "
                 "say why)\n";
    return kRuntime;
  }
  return kOk;
}

int grazing(const calibrate::StudyOptions& o) {
  const calibrate::GrazingStudy s = calibrate::run_grazing_study(o);
  std::cout << "grazing impact, theta 30 deg, eta 0.1, b 1, no damping: " << s.rows.size() << " impacts\n"
            << "largest energy ratio - 1: " << s.worst_gain << " (" << s.worst_where << ")"
            << (s.worst_gain > 0 ? ": the integrator's head-on error, see docs/studies.md" : ": no energy gained")
            << "\n";
  for (const auto& f : s.files) std::cout << "wrote " << f << "\n";
  return kOk;
}

int timestep(const StudyArgs& a, const calibrate::StudyOptions& o) {
  db::Store store(a.db);
  const calibrate::TimestepStudy s = calibrate::run_timestep_study(store, o);
  std::cout << "job " << s.job << " in " << a.db << ": " << s.tasks << " tasks (" << s.reused << " reused, " << s.ran
            << " run now";
  // Failed in an earlier run and kept (the runner retries failures only when asked):
  // here the factors past the stability limit, which fail by design.
  if (const int kept = s.tasks - s.reused - s.ran; kept > 0) std::cout << ", " << kept << " failed in an earlier run";
  std::cout << ")\n";
  std::cout << "series           dt_factor  status    drift/sim-s (worst)  mean +- sd of replicas   wall-s/sim-s  pareto\n";
  bool past_shown = false, failed_shown = false;
  for (const auto& p : s.points) {
    char line[240];
    // A run past its law's critical step that did not blow up within the run is no
    // stable step: friction's dissipation can hide the growth for a while.
    const std::string status = calibrate::timestep_status(p, s);
    past_shown = past_shown || status == "ran*";
    failed_shown = failed_shown || status == "failed";
    if (p.ok)
      std::snprintf(line, sizeof line, "%-16s %9.3g  %-8s  %19.3e  %10.2e +- %8.2e  %12.3e  %s\n",
                    p.friction ? "friction+rolling" : "frictionless", p.dt_factor, status.c_str(), p.drift,
                    p.drift_mean, p.drift_sd, p.cost, p.pareto ? "*" : "");
    else  // an unstable run has no drift or cost to show
      std::snprintf(line, sizeof line, "%-16s %9.3g  %-8s  %19s  %22s  %12s\n", p.friction ? "friction+rolling" : "frictionless",
                    p.dt_factor, "unstable", "-", "-", "-");
    std::cout << line;
  }
  std::cout << "worst: the replica with the largest |drift| (frictionless) or the largest gain (friction+rolling, "
               "which dissipates: only a gain is error)\n";
  std::cout << "ok: finished, short of the failure region (" << calibrate::kTimestepExplode
            << " x the tolerance); the recommendation asks for the tolerance itself\n";
  if (failed_shown)
    std::cout << "failed: finished, but its energy drift exceeds " << calibrate::kTimestepExplode
              << " x the tolerance per simulated second (the charts' failure region)\n";
  if (past_shown)
    std::cout << "ran*: past its law's critical step (frictionless " << s.critical_factor_frictionless << ", "
              << s.critical_mode_full << " " << s.critical_factor_full
              << "), and no instability showed within the run: not a stable step\n";
  std::cout << s.recommendation << "\n";
  for (const auto& f : s.files) std::cout << "wrote " << f << "\n";
  // No factor passed: the study found no step to recommend, which a script must see.
  if (s.recommended_factor <= 0.0) {
    std::cerr << "demcal: study timestep: no dt_factor passed at tolerance " << s.tolerance
              << " (the table and charts above show where each failed)\n";
    return kRuntime;
  }
  return kOk;
}

// The study's options from the command line, refusing those that do not apply to it
// (bad input: exit 2 before anything is written).
calibrate::StudyOptions study_options(const StudyArgs& a) {
  const auto& names = calibrate::study_names();
  if (std::find(names.begin(), names.end(), a.name) == names.end()) {
    std::string all;
    for (const auto& n : names) all += (all.empty() ? "" : ", ") + n;
    throw jobs::JobError("study", "unknown study \"" + a.name + "\" (expected one of: " + all + ")");
  }
  calibrate::StudyOptions o;
  o.out_dir = a.out.empty() ? default_out_dir(a.db) + "/study-" + a.name : a.out;
  o.quick = a.quick;
  o.workers = a.workers;
  o.tolerance = a.tolerance;
  o.replicas = a.replicas;
  o.knobs = a.knobs;
  o.smoothed_peak = a.peak == "smoothed";
  o.terminal = isatty(STDERR_FILENO) != 0;
  o.log = &std::cerr;
  if (!is_fidelity(a.name) && (a.replicas > 0 || !a.knobs.empty() || !a.references.empty()))
    throw jobs::JobError("study", "--replicas, --knobs and --reference apply to the fidelity and repose-fidelity studies only");
  if (a.name != "fidelity" && a.peak_given)
    throw jobs::JobError("--peak", "study " + a.name + " has no peak strength to judge: --peak applies to the (triaxial) "
                                   "fidelity study only");
  if (a.name == "grazing" && a.tolerance > 0)
    throw jobs::JobError("--tolerance", "the grazing study has no tolerance: any energy gained is reported");
  if (a.name == "grazing" && a.db_given)
    throw jobs::JobError("--db", "the grazing study stores nothing in a database: its CSV and charts go to --out");
  if (is_fidelity(a.name)) {
    for (const auto& r : a.references)
      if (!o.reference.insert(parse_reference(r)).second)
        throw jobs::JobError("--reference", "\"" + r + "\": a second reference for the same knob; give one");
    calibrate::check_fidelity_options(a.name, o);  // bad knobs: exit 2 before anything is written
  }
  return o;
}

int study(const StudyArgs& a) {
  const calibrate::StudyOptions o = study_options(a);
  if (!jobs::gnuplot_on_path())
    throw std::runtime_error("study " + a.name + " draws its charts with gnuplot, which is not on PATH: install it "
                             "(apt-get install gnuplot-nox; scripts/setup.sh does) and run the study again; nothing was run");
  // The option whose path the output folder comes from (grazing has no database).
  const std::string flag = a.name != "grazing" ? out_flag(a.out) : "--out";
  // The database checked first (nothing made yet when it is refused), then the
  // output folder made and locked, then its sub-folders made, all before the database
  // is: a file or a link in their way would otherwise stop the study after it had
  // recorded its jobs, and a study refused by the lock leaves nothing of its own.
  if (a.name != "grazing") db::check_file(a.db), db::check_writable(a.db);
  require_writable_dir(flag, o.out_dir);
  jobs::make_folder(o.out_dir, flag, "folder");
  // Held until the study returns: its charts' data and scripts have fixed names.
  const jobs::FolderLock lock(o.out_dir, flag);
  if (!lock.unsupported().empty())
    std::cerr << "demcal: warning: " << flag << ": " << o.out_dir << " cannot be locked (" << lock.unsupported()
              << "): a second study into it at the same time would not be stopped\n";
  for (const char* sub : {"tasks", "jobs"}) {
    if ((!is_fidelity(a.name) && std::string(sub) == "jobs") || (a.name == "grazing" && std::string(sub) == "tasks"))
      continue;
    jobs::make_folder((fs::path(o.out_dir) / sub).string(), flag, "folder");
  }
  if (is_fidelity(a.name)) return fidelity(a, o);
  if (a.name == "grazing") return grazing(o);
  return timestep(a, o);
}

}  // namespace

void add_study(CLI::App& app, int& exit_code) {
  auto* cmd = app.add_subcommand(
      "study", "Speed-against-accuracy studies: timestep (seed Fig. 2.6 over dt factors, stored in the database), "
               "grazing (oblique impacts: energy must never be gained), fidelity (triaxial) and repose-fidelity "
               "(error against wall time, one knob at a time); charts with gnuplot");
  auto a = std::make_shared<StudyArgs>();
  cmd->add_option("NAME", a->name, "timestep, grazing, fidelity or repose-fidelity")->required();
  cmd->add_option("--db", a->db, "SQLite database (timestep, fidelity, repose-fidelity)")->check(kDbPath)->capture_default_str();
  cmd->add_option("--out", a->out, "where charts and CSV go (default: demcal-out/study-NAME next to the database)")->check(kPlainPath);
  cmd->add_flag("--quick", a->quick, "a small, fast version (seconds): for tests and a first look");
  cmd->add_option("--workers", a->workers, "worker processes (default: the core count)")->transform(kWholeNumber)->check(CLI::Range(1, 4096));
  cmd->add_option("--tolerance", a->tolerance,
                  "timestep: accepted |relative energy drift| per simulated second (default 0.1); "
                  "fidelity, repose-fidelity: accepted error + replica sd in degrees (default 2)")
      ->check(kPositiveFinite);
  cmd->add_option("--replicas", a->replicas, "fidelity studies: packings (seeds 1..R) per setting (default 3, --quick 1)")
      ->transform(kWholeNumber)->check(CLI::Range(1, 1000));
  cmd->add_option("--knobs", a->knobs,
                  "fidelity studies: knobs to vary, comma-separated (fidelity: particles, rate, dt, density, stiffness; "
                  "repose-fidelity: depth, column, stiffness, dt; default all)")
      ->delimiter(',');
  cmd->add_option("--reference", a->references,
                  "fidelity studies: KNOB=VALUE, the setting errors are measured against (default: the knob's most "
                  "expensive setting); a value not in the knob's list is added to it")
      ->delimiter(',');
  cmd->add_option("--peak", a->peak,
                  "fidelity: the phi_peak the errors are taken on: raw (phi_peak_deg, the design's definition) or "
                  "smoothed (phi_peak_smoothed_deg, the peak of its running mean over 5 rows, " +
                      calibrate::running_mean_vs_spike() +
                      "); the same tasks, with the charts, CSV and recommendation named fidelity-smoothed-peak")
      ->check(CLI::IsMember({"raw", "smoothed"}))
      ->capture_default_str();
  cmd->callback([a, cmd, &exit_code] {
    a->db_given = cmd->count("--db") > 0;
    a->peak_given = cmd->count("--peak") > 0;
    exit_code = guarded("", [&] { return study(*a); });
  });
}

}  // namespace demcal::cli
