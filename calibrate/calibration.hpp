#pragma once
// The calibration as the CLI runs it: pick the job holding each target's metric,
// build its response surface and surrogate, invert, store the result in `fits`;
// optionally refine by running the DEM around the candidate and fitting again.
#include "inversion.hpp"

#include "db/store.hpp"
#include "jobs/query.hpp"

#include <functional>
#include <ostream>
#include <string>
#include <vector>

namespace demcal::calibrate {

struct FitRequest {
  std::vector<Target> targets;
  std::vector<std::string> jobs;       // empty: every job in the store
  std::vector<jobs::Where> where;      // pins parameters other than theta, eta
  FitOptions options;
};

struct Calibration {
  std::vector<ResponseSurface> surfaces;  // one per target
  std::vector<Model> models;              // one per target
  FitResult result;
};

// The job holding `metric` among `jobs` (every base job when empty). Throws
// JobError naming `metric_flag` (no job has it) or --job (several have it).
std::string job_for_metric(db::Store& store, const std::string& metric, const std::vector<std::string>& jobs,
                           const std::vector<jobs::Where>& where, const std::string& metric_flag = "--target");

// Throws JobError for bad input (unknown metric, no data, grids that do not overlap).
Calibration calibrate(db::Store& store, const FitRequest& request);
// A fit across jobs assumes one material: the material parameters other than theta
// and eta that the jobs' tasks do not share, as a warning ("" when they share all).
std::string material_mismatch(db::Store& store, const std::vector<std::string>& jobs);

// What a stored fit holds: the targets, the method and the result (with the jobs,
// surrogates, round and pinned parameters).
struct FitRecord {
  nlohmann::json targets;
  std::string method;
  nlohmann::json result;
};
FitRecord fit_record(const FitRequest& request, const Calibration& cal, int round,
                     const nlohmann::json& extra = nlohmann::json::object());

// Stores the fit (round 0: the plain fit) and returns its id.
std::int64_t store_fit(db::Store& store, const FitRequest& request, const Calibration& cal, int round,
                       const nlohmann::json& extra = nlohmann::json::object());

// Refinement: DEM runs at the candidate and a few neighbours, appended as the
// job's sub-job <job>.refine<round>; `run_points` does the running. Rounds are
// numbered on from the last one stored, so a later `fit --refine` adds to the
// earlier rounds instead of replacing them; `resume_round` finishes a stored round
// whose runs were interrupted.
struct RefinePoint {
  double theta, eta;
};
using PointRunner = std::function<void(db::Store& store, const std::string& job, int round, const std::vector<RefinePoint>& points)>;
using RoundResumer = std::function<void(db::Store& store, const std::string& sub_job)>;

struct RefineOptions {
  int rounds = 0;           // new rounds to run
  double tolerance = 0.02;  // stop when the candidate moves less than this fraction of the grid range on both axes
  PointRunner run_points;
  RoundResumer resume_round;  // unset: an unfinished stored round is left as it is
  std::ostream* log = nullptr;
};

struct RefineRound {
  int round = 0;
  bool resumed = false;             // a stored round finished, not a new one
  std::vector<RefinePoint> points;  // empty for a resumed round
  double theta = kNaN, eta = kNaN, move = kNaN;  // candidate after the round; move in fractions of the range
  bool ok = false;
  std::int64_t fit_id = 0;
};

// The candidate and three neighbours forming a rectangle with it, spaced by the
// grid spacing / 2^round towards the inside of the box.
std::vector<RefinePoint> refine_points(const ResponseSurface& rs, double theta, double eta, int round);

// Finishes the last stored round of any of the fit's jobs that has unfinished runs,
// then runs new rounds until the candidate moves less than the tolerance, a fit
// fails, or `rounds` is reached; `cal` holds the last calibration. Each round's fit
// is stored.
std::vector<RefineRound> refine(db::Store& store, const FitRequest& request, Calibration& cal, const RefineOptions& options);

// The real runner: a sub-job of `job` whose grid is the points' theta x eta values
// (other axes as in the job, except those `where` pins: those take the pinned value
// alone, as the fit read only them), run by jobs::run_job into the store.
PointRunner dem_point_runner(const std::string& out_dir, int workers, std::ostream* log,
                             const std::vector<jobs::Where>& where = {});
// The real resumer: runs the sub-job's stored spec again, which runs only its
// unfinished tasks.
RoundResumer dem_round_resumer(const std::string& out_dir, int workers, std::ostream* log);

}  // namespace demcal::calibrate
