#pragma once
// Speed-against-accuracy studies (issue 9; one file each: timestep_study.cpp,
// grazing_study.cpp, fidelity_study.cpp): `demcal study timestep|grazing|fidelity|repose-fidelity`.
//
// timestep: the seed's Fig. 2.6 collision test as a job over a grid of dt factors,
// frictionless and with friction + rolling resistance, run by the normal runner
// into the database; charts energy drift against the factor (log-log, the
// engine's critical steps and the failure region marked) and drift against cost
// (wall seconds per simulated second, Pareto front marked); recommends the
// largest factor whose drift stays within the tolerance.
//
// grazing: oblique impacts on a wall, a fixed and a free sphere across incidence
// angles (engine/scenes/grazing_impact.hpp); charts the energy ratio.
//
// fidelity (triaxial) and repose-fidelity: one knob at a time around a baseline,
// each knob one job (or one job per setting when a setting sets several
// parameters) that the normal runner executes into the database; the baseline
// point has the same task key in every knob's job, so it runs once. Per knob:
// |metric - reference| against the knob's most expensive setting (or a given
// one), replica spread, wall time; a chart of error against wall time (Pareto
// front and failed tasks marked) and the cheapest setting within the tolerance.
#include "db/store.hpp"
#include "jobs/query.hpp"

#include <cmath>
#include <map>
#include <ostream>
#include <string>
#include <vector>

namespace demcal::calibrate {

using jobs::ResultRow;

struct StudyOptions {
  std::string out_dir;        // charts and CSV go here (created)
  bool quick = false;         // small and fast: for tests and a first look
  int workers = 0;            // runner processes; 0: the core count
  double tolerance = 0.0;     // timestep: |relative drift| per simulated second; fidelity: deg; 0: the default
  // fidelity studies only
  int replicas = 0;                          // packings (seeds 1..R) per setting; 0: 3 (quick: 1)
  std::vector<std::string> knobs;            // knobs to run; empty: all
  std::map<std::string, double> reference;   // knob -> reference setting; absent: the knob's most expensive
  // fidelity (triaxial) only: judge phi_peak by phi_peak_smoothed_deg, the peak of its
  // running mean, which a spike of one or two rows in the walls' stress moves by at most two fifths of its height. The tasks
  // are the same; the charts, CSV and recommendation are named <name>-smoothed-peak.
  bool smoothed_peak = false;
  bool terminal = false;
  std::ostream* log = nullptr;
};

struct TimestepPoint {
  double dt_factor = 0;
  bool friction = false;      // true: theta 30 deg, eta 0.1 (rolling active); false: frictionless
  bool ok = false;            // false: the run went unstable (or failed)
  std::string error;
  // Over the replicas (different random velocities and grains): drift is the relative
  // energy drift per simulated second of the worst replica (largest |drift| without
  // friction, largest gain with it; signed), drift_mean / drift_sd their mean and
  // spread. One replica's drift is noise-dominated: a gas of 1,250 grains over 1 ms
  // gave +0.10 to +0.19 /s at k = 0.3 across four seeds.
  // dt: the step, mean over the replicas (each sample's smallest grain sets its own).
  double dt = 0, drift = 0;
  double drift_mean = 0, drift_sd = 0;
  int replicas = 0;
  double max_relative_error = 0;  // the worst replica's largest |E/E0 - 1|
  double cost = 0;                // wall seconds per simulated second, mean over replicas
  bool pareto = false;        // on its series' Pareto front (cost, |drift|)
};

struct TimestepStudy {
  std::string job;
  int tasks = 0, reused = 0, ran = 0;  // from the runner: reused = already done before this run
  std::vector<TimestepPoint> points;
  double tolerance = 0;
  double critical_factor_frictionless = 0;  // the engine's limit / sqrt(m_min/Kn), normal mode
  double critical_factor_full = 0;          // with friction and rolling (governing mode)
  std::string critical_mode_full;
  double recommended_factor = 0;            // 0: none passed
  bool capped_at_critical = false;          // a larger factor passed, but past the full law's critical step
  std::string recommendation;               // the sentence printed
  std::vector<std::string> files;           // charts and CSV written
};

// Runs (or reuses) the study's tasks in `store`; returns what it charted.
TimestepStudy run_timestep_study(db::Store& store, const StudyOptions& options);

// One factor of one series from its replicas' results (metrics drift_per_simulated_s,
// dt, max_relative_error, wall_s_per_simulated_s): failed if any replica failed or
// drifted non-finitely, else the worst replica's drift with the mean and sd beside it.
TimestepPoint timestep_point(bool friction, double factor, const std::vector<ResultRow>& rows);
// Where the method fails: unstable, or the worst replica's energy grew (with friction;
// either way without) by more than kTimestepExplode tolerances per simulated second:
// the charts' failure region and the CSV's failure column.
constexpr double kTimestepExplode = 100.0;
bool timestep_failed(const TimestepPoint& p, double tolerance);
// How a point reads in the printed table and the CSV's status column, alike:
// "unstable" (a replica stopped on an instability), "failed" (finished, with a drift
// in the failure region), "ran*" (past its law's critical step with no instability
// showing within the run: no stable step) or "ok".
std::string timestep_status(const TimestepPoint& p, const TimestepStudy& s);

struct GrazingStudy {
  struct Row {
    std::string target;
    double incidence_deg, dt_fraction, energy_ratio, max_energy_ratio, rebound_deg;
    bool slid;
  };
  std::vector<Row> rows;
  double worst_gain = 0;             // largest energy_ratio - 1 over all rows
  std::string worst_where;
  std::vector<std::string> files;
};
GrazingStudy run_grazing_study(const StudyOptions& options);

// One setting of one knob, over its replicas.
struct FidelityPoint {
  double value = 0;              // the knob's setting
  std::string label;             // as printed ("500", "0.0003")
  bool baseline = false, reference = false;
  int replicas = 0, failed = 0;  // tasks; failed: failed, or done without the metric
  std::vector<std::string> failures;  // "seed 2: not_converged in stage ...", one per failed task
  std::vector<std::string> spikes;    // "seed 3: phi_peak 46.33 deg, the running mean's peak 38.84 deg"
  double wall_s = NAN;           // mean engine wall seconds (of the ok replicas; all failed: of the failed)
  double work = NAN;             // mean particles x steps of the ok replicas: the load-independent cost
                                 // "cheapest" and the Pareto front use (wall time on a shared machine is noisy)
  std::vector<double> mean, sd, error;  // per metric (FidelityStudy::metrics); error = |mean - reference mean|
  double score = NAN;            // max over metrics of error + sd: what the tolerance is applied to
  bool pass = false, pareto = false, recommended = false;
};

struct FidelityKnob {
  std::string name;              // "particles"
  std::string param;             // job parameter(s) it sets, e.g. "particles" or "column_width,column_height"
  std::string what;              // axis words for charts
  std::vector<FidelityPoint> points;  // by setting, ascending
  std::vector<std::string> jobs;      // job names (one per knob, or one per setting)
  std::string recommendation;    // the sentence printed
  double recommended = NAN;      // NaN: none within tolerance
  // Whether anything was compared with the reference (false: it failed, or every other
  // setting did): a knob not judged has no answer, not even "keep the reference".
  bool judged = false;
  std::string chart;             // PNG
};

struct FidelityStudy {
  std::string name;              // "fidelity" | "repose-fidelity"
  std::string stem;              // what its charts, CSV and recommendation are named from
  bool smoothed_peak = false;    // phi_peak errors taken on phi_peak_smoothed_deg
  std::string scene;
  std::vector<std::string> metrics;
  double tolerance = 0;
  int replicas = 0;
  int tasks = 0, reused = 0, ran = 0;   // distinct tasks; ran now; reused = tasks - ran (done or failed before)
  std::vector<FidelityKnob> knobs;
  std::vector<std::string> job_files;   // written into out_dir/jobs, runnable with `demcal run`
  std::vector<std::string> failures;    // "particles=2000 seed 2: ..." every failed task
  std::vector<std::string> spikes;      // "dt=0.15 seed 3: ..." every replica whose peak rests on a spike
  // Finished tasks whose run warned (of any kind, spikes included), those of them not
  // at critical state and not quasi-static, and the sentence that says so (empty: none).
  int warned = 0, not_critical = 0, not_quasi_static = 0, finished = 0;
  std::string warnings_note;
  // Whether some knob was judged against its reference (none: the study has no
  // answer, exit 1; a knob judged with no setting within tolerance keeps its reference).
  bool any_judged() const;
  std::string baseline;                 // "particles 500, rate 0.0003, ..."
  std::string recommendation;           // summary line
  std::vector<std::string> files;
};

// What the list of replicas whose peak rests on a spike is headed with (table and file).
std::string spike_heading();

// The knobs a fidelity study has (for errors and help), and a check of the
// options that throws JobError ("--knobs", "--reference", ...) before anything is
// written. `name`: "fidelity" or "repose-fidelity".
std::vector<std::string> fidelity_knob_names(const std::string& name);
void check_fidelity_options(const std::string& name, const StudyOptions& options);
FidelityStudy run_fidelity_study(db::Store& store, const std::string& name, const StudyOptions& options);

// The studies `demcal study` knows, for help texts and errors.
inline const std::vector<std::string>& study_names() {
  static const std::vector<std::string> names = {"timestep", "grazing", "fidelity", "repose-fidelity"};
  return names;
}

}  // namespace demcal::calibrate
