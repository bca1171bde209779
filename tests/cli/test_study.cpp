// demcal study (issue 9): quick versions run in seconds, write their charts and a
// recommendation, store the timestep tasks in the database, and bad input fails
// with a clear message and exit code 2.
#include "calibrate/study.hpp"
#include "cli_util.hpp"

#include <cmath>
#include <map>
#include <fcntl.h>
#include <sqlite3.h>
#include <sstream>
#include <sys/file.h>
#include <unistd.h>

using namespace demcal::test;

TEST(CliStudy, TimestepQuickWritesChartsRecommendationAndStoresTasks) {
  TempDir d;
  const Result r = run_demcal({"study", "timestep", "--quick", "--workers", "2", "--db", "s.db", "--out", "charts"},
                              d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err << r.out;
  for (const char* f : {"timestep_drift.png", "timestep_cost.png", "timestep.csv", "timestep_recommendation.txt"}) {
    const fs::path p = d.path / "charts" / f;
    EXPECT_TRUE(fs::exists(p) && fs::file_size(p) > 0) << f;
  }
  EXPECT_NE(r.out.find("recommended dt_factor"), std::string::npos) << r.out;
  // Past both critical factors the runs are marked unstable, not hidden.
  EXPECT_NE(r.out.find("unstable"), std::string::npos) << r.out;
  // The tasks went through the runner into the database: query sees them.
  const Result q = run_demcal({"query", "--db", "s.db", "--job", "study-timestep-quick", "--format", "csv"},
                              d.path.string());
  EXPECT_EQ(q.rc, 0) << q.err;
  EXPECT_NE(q.out.find("drift_per_simulated_s"), std::string::npos) << q.out;
  const std::string first_recommendation = slurp(d.file("charts/timestep_recommendation.txt"));
  // Running it again runs nothing: finished tasks are reused, failed (unstable)
  // ones are kept as failed.
  const Result again = run_demcal({"study", "timestep", "--quick", "--db", "s.db", "--out", "charts"}, d.path.string());
  EXPECT_EQ(again.rc, 0) << again.err;
  EXPECT_NE(again.out.find("reused, 0 run now, 4 failed in an earlier run)"), std::string::npos) << again.out;
  EXPECT_EQ(slurp(d.file("charts/timestep_recommendation.txt")), first_recommendation);
}

// Two studies into one folder would overwrite each other's chart data while gnuplot
// reads it: the second is refused, naming the holder, before its database is made.
TEST(CliStudy, ASecondStudyIntoAFolderInUseIsRefused) {
  TempDir d;
  fs::create_directories(d.path / "charts");
  const int fd = ::open(d.file("charts/.demcal-lock").c_str(), O_RDWR | O_CREAT, 0644);
  ASSERT_GE(fd, 0);
  ASSERT_EQ(::write(fd, "pid 4242 on node7\n", 17), 17);
  ASSERT_EQ(::flock(fd, LOCK_EX | LOCK_NB), 0);
  Result r = run_demcal({"study", "grazing", "--out", "charts"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--out: another demcal (pid 4242 on node7) is writing into charts: wait for it to finish, or give this "
                       "one another folder"),
            std::string::npos) << r.err;
  r = run_demcal({"study", "timestep", "--quick", "--db", "s.db", "--out", "charts"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_FALSE(fs::exists(d.file("s.db"))) << "refused before the database was made";
  EXPECT_FALSE(fs::exists(d.file("charts/tasks"))) << "nothing of its own left in the folder in use";
  ::close(fd);  // released: the study runs
  r = run_demcal({"study", "grazing", "--out", "charts"}, d.path.string());
  EXPECT_EQ(r.rc, 0) << r.err;
}

TEST(CliStudy, TimestepRecommendationFollowsItsRule) {
  // The rule, re-applied to the study's own CSV: the largest factor such that at it
  // and at every smaller factor the frictionless run is stable with |drift| within
  // the tolerance and the run with friction and rolling is stable and gains no
  // more than the tolerance. A tolerance loose enough that more than one factor
  // passes ("largest" is exercised) and tight enough that some fail (the stop is).
  TempDir d;
  const double tol = 2.0;
  const Result r = run_demcal({"study", "timestep", "--quick", "--workers", "2", "--db", "s.db", "--out", "c",
                               "--tolerance", "2"},
                              d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err << r.out;
  std::map<double, bool> frictionless_pass, friction_pass;
  std::istringstream csv(slurp(d.file("c/timestep.csv")));
  std::string line;
  std::getline(csv, line);  // header
  while (std::getline(csv, line)) {
    std::vector<std::string> f;
    std::stringstream ls(line);
    for (std::string cell; f.size() < 6 && std::getline(ls, cell, ',');) f.push_back(cell);
    ASSERT_EQ(f.size(), 6u) << line;
    const double factor = std::stod(f[1]), drift = std::stod(f[5]);
    // The status column reads as the printed table does: a failure is never "ok".
    EXPECT_EQ(f[4] == "1", f[3] == "failed" || f[3] == "unstable") << line;
    bool row_found = false;
    std::istringstream table(r.out);
    for (std::string row; std::getline(table, row);) {
      std::istringstream cells(row);
      std::string series, factor_text, status;
      if (!(cells >> series >> factor_text >> status)) continue;
      if (series != (f[0] == "frictionless" ? "frictionless" : "friction+rolling")) continue;
      try {
        if (std::abs(std::stod(factor_text) - std::stod(f[1])) > 1e-9 * std::stod(f[1])) continue;
      } catch (const std::exception&) {
        continue;
      }
      row_found = true;
      EXPECT_EQ(status, f[3]) << row << "\n" << line;
    }
    EXPECT_TRUE(row_found) << line;
    if (f[0] == "frictionless") frictionless_pass[factor] = f[3] == "ok" && std::abs(drift) <= tol;
    else friction_pass[factor] = f[3] == "ok" && drift <= tol;
  }
  ASSERT_GE(frictionless_pass.size(), 3u);
  // ... and no factor past the full law's critical one, which the engine refuses a job.
  const auto crit_at = r.out.find("(frictionless, normal mode) and ");
  ASSERT_NE(crit_at, std::string::npos) << r.out;
  const double critical_full = std::stod(r.out.substr(crit_at + 32));
  double expected = 0.0;
  for (const auto& [factor, ok] : frictionless_pass) {
    if (factor > critical_full || !ok || !friction_pass.count(factor) || !friction_pass[factor]) break;
    expected = factor;
  }
  EXPECT_GT(expected, frictionless_pass.begin()->first) << "at least two factors should pass at this tolerance";
  const auto at = r.out.find("recommended dt_factor ");
  ASSERT_NE(at, std::string::npos) << r.out;
  EXPECT_NEAR(std::stod(r.out.substr(at + 22)), expected, 1e-6 * expected) << r.out;
  // Some factor fails at this tolerance, or the rule's "stop at the first failure" is untested.
  bool any_fail = false;
  for (const auto& [factor, ok] : frictionless_pass) any_fail |= !ok || !friction_pass[factor];
  EXPECT_TRUE(any_fail);

  // A tolerance so loose that factors past the critical step pass too (the dilute gas's
  // brief contacts survive them): the recommendation stops below it and says why.
  const Result loose = run_demcal({"study", "timestep", "--quick", "--db", "s.db", "--out", "c", "--tolerance", "1000"},
                                  d.path.string());
  ASSERT_EQ(loose.rc, 0) << loose.err << loose.out;
  const auto rec = loose.out.find("recommended dt_factor ");
  ASSERT_NE(rec, std::string::npos) << loose.out;
  EXPECT_LE(std::stod(loose.out.substr(rec + 22)), critical_full) << loose.out;
  EXPECT_NE(loose.out.find("but it lies past the critical step of the full law"), std::string::npos) << loose.out;

  // A tolerance no factor meets: said, and the exit code tells a script.
  const Result none = run_demcal({"study", "timestep", "--quick", "--db", "s.db", "--out", "c", "--tolerance", "1e-12"},
                                 d.path.string());
  EXPECT_EQ(none.rc, 1) << none.err << none.out;
  EXPECT_NE(none.out.find("no dt_factor passed"), std::string::npos) << none.out;
  EXPECT_NE(none.err.find("no dt_factor passed at tolerance 1e-12"), std::string::npos) << none.err;
}

TEST(CliStudy, GrazingQuickChartsTheEnergyRatio) {
  TempDir d;
  const Result r = run_demcal({"study", "grazing", "--quick", "--out", "g"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_TRUE(fs::exists(d.path / "g" / "grazing_energy.png"));
  EXPECT_NE(slurp(d.file("g/grazing.csv")).find("free_sphere"), std::string::npos);
  EXPECT_NE(r.out.find("largest energy ratio"), std::string::npos) << r.out;
}

TEST(CliStudy, UnknownStudyIsBadInput) {
  TempDir d;
  Result r = run_demcal({"study", "fidelty"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("unknown study \"fidelty\""), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("timestep"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(d.path / "demcal.db"));  // nothing written
  r = run_demcal({"study"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  r = run_demcal({"study", "timestep", "--tolerance", "-1"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--tolerance: must be a positive finite number, got \"-1\""), std::string::npos) << r.err;
  EXPECT_LT(r.err.size(), 200u) << r.err;  // CLI11's own range wrote DBL_MAX in full
  // Options a study does not use are refused, not ignored.
  r = run_demcal({"study", "grazing", "--quick", "--tolerance", "0.1"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--tolerance: the grazing study has no tolerance"), std::string::npos) << r.err;
  r = run_demcal({"study", "grazing", "--quick", "--db", "g.db"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--db: the grazing study stores nothing in a database"), std::string::npos) << r.err;
  // Its default output folder comes from --out's default, not from a --db it refuses.
  write(d.file("demcal-out"), "a file where the folder would go");
  r = run_demcal({"study", "grazing", "--quick"}, d.path.string());
  EXPECT_EQ(r.rc, 2) << r.err;
  EXPECT_NE(r.err.find("error: --out:"), std::string::npos) << r.err;
  fs::remove(d.file("demcal-out"));
  // A database that cannot be made is refused before any folder is.
  r = run_demcal({"study", "timestep", "--quick", "--db", "nodir/t.db", "--out", "tsq"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("nodir"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(d.path / "tsq"));
  EXPECT_FALSE(fs::exists(d.path / "demcal-out"));
  // Without gnuplot a study would run its tasks and fail at its first chart: it says so
  // before running anything.
  fs::create_directories(d.path / "empty-bin");
  r = run_demcal({"study", "timestep", "--quick", "--db", "t.db", "--out", "nognu"}, d.path.string(),
                 {{"PATH", (d.path / "empty-bin").string()}});
  EXPECT_EQ(r.rc, 1) << r.err;
  EXPECT_NE(r.err.find("draws its charts with gnuplot, which is not on PATH"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(d.path / "nognu"));
  EXPECT_FALSE(fs::exists(d.path / "t.db"));
}

// The triaxial fidelity study, quick and restricted to the dt knob: the baseline
// 0.3, the reference 0.15 and 2.0 (past the engine's critical step: every replica
// fails at once). Two replicas, one worker: a few seconds on one core.
TEST(CliStudy, FidelityQuickChartsRecommendsListsFailuresAndReuses) {
  TempDir d;
  const std::vector<std::string> args = {"study", "fidelity", "--quick", "--knobs", "dt", "--replicas", "2",
                                         "--workers", "1", "--db", "s.db", "--out", "f"};
  const Result r = run_demcal(args, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err << r.out;
  for (const char* f : {"fidelity-dt_dt.png", "fidelity-dt.csv", "fidelity-dt_recommendation.txt",
                        "jobs/study-fidelity-quick-dt.json"}) {
    const fs::path p = d.path / "f" / f;
    EXPECT_TRUE(fs::exists(p) && fs::file_size(p) > 0) << f;
  }
  EXPECT_NE(r.out.find("job file f/jobs/study-fidelity-quick-dt.json"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("6 tasks in s.db (0 reused, 6 run now)"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("dt: "), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("recommended settings (fidelity, one knob at a time"), std::string::npos) << r.out;
  // The failed setting is listed, counted and drawn, not dropped.
  EXPECT_NE(r.out.find("failed tasks (2)"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("dt=2 seed 1: "), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("dt=2 seed 2: "), std::string::npos) << r.out;
  EXPECT_NE(slurp(d.file("f/fidelity-dt_dt.dat")).find("\"2: 2/2 failed\""), std::string::npos);
  // The quick study's fast shear warns on every task (not quasi-static): counted, with
  // where to see them, in the output and the recommendation file.
  EXPECT_NE(r.out.find("warnings: 4 of the 4 finished tasks carry warnings ("), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("4 not quasi-static"), std::string::npos) << r.out;
  EXPECT_NE(slurp(d.file("f/fidelity-dt_recommendation.txt")).find("warnings: 4 of the 4"), std::string::npos);
  // The script kept beside the chart redraws it from its own folder: names, no paths,
  // no hidden part.
  const std::string gp = slurp(d.file("f/fidelity-dt_dt.gp"));
  EXPECT_NE(gp.find("set output 'fidelity-dt_dt.png'"), std::string::npos) << gp;
  EXPECT_NE(gp.find("plot 'fidelity-dt_dt.dat'"), std::string::npos) << gp;
  EXPECT_EQ(gp.find(".part"), std::string::npos) << gp;
  EXPECT_EQ(gp.find("'f/"), std::string::npos) << gp;
  const std::string csv = slurp(d.file("f/fidelity-dt.csv"));
  EXPECT_NE(csv.find("phi_peak_deg_error"), std::string::npos) << csv;
  EXPECT_NE(csv.find("dt,2,0,0,2,2,"), std::string::npos) << csv;
  // The tasks are in the database under the written job, which validates as is.
  const Result q = run_demcal({"query", "--db", "s.db", "--job", "study-fidelity-quick-dt", "--format", "csv"},
                              d.path.string());
  EXPECT_EQ(q.rc, 0) << q.err;
  EXPECT_NE(q.out.find("phi_cv_deg"), std::string::npos) << q.out;
  EXPECT_EQ(run_demcal({"validate", "f/jobs/study-fidelity-quick-dt.json"}, d.path.string()).rc, 0);
  const std::string first = slurp(d.file("f/fidelity-dt_recommendation.txt"));
  // Again: every task is reused (the failed ones stay failed), nothing runs.
  const Result again = run_demcal(args, d.path.string());
  ASSERT_EQ(again.rc, 0) << again.err;
  EXPECT_NE(again.out.find("6 tasks in s.db (6 reused, 0 run now)"), std::string::npos) << again.out;
  EXPECT_EQ(slurp(d.file("f/fidelity-dt_recommendation.txt")), first);
  // The failing setting as the reference: no answer, said, and the exit code is 1.
  const std::vector<std::string> no_answer = {"study", "fidelity", "--quick", "--knobs", "dt", "--replicas", "2",
                                              "--workers", "1", "--db", "s.db", "--out", "g", "--reference", "dt=2"};
  const Result none = run_demcal(no_answer, d.path.string());
  EXPECT_EQ(none.rc, 1) << none.err << none.out;
  EXPECT_NE(none.out.find("dt: no recommendation: the reference 2 failed in every replica"), std::string::npos)
      << none.out;
  EXPECT_NE(none.err.find("no knob could be judged against its reference"), std::string::npos) << none.err;
  // A replica whose peak rests on a spike (its phi_peak 5 deg above the running mean's
  // peak, as a buckling wall chain makes it) is marked, counted and listed: one such
  // replica can set a setting's mean, spread and verdict. The quick study's inertial
  // shear spikes by itself (up to 20 deg at its start), so the stored peaks are first
  // set to their smoothed values, then one is raised.
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(d.file("s.db").c_str(), &db), SQLITE_OK);
  const std::string smoothed =
      "(SELECT m.value FROM metrics m WHERE m.task_id = metrics.task_id AND m.name = 'phi_peak_smoothed_deg')";
  const std::string flatten = "UPDATE metrics SET value = " + smoothed + " WHERE name = 'phi_peak_deg'";
  EXPECT_EQ(sqlite3_exec(db, flatten.c_str(), nullptr, nullptr, nullptr), SQLITE_OK) << sqlite3_errmsg(db);
  EXPECT_EQ(sqlite3_changes(db), 4);  // the four tasks that ran to the end
  const std::string raise = "UPDATE metrics SET value = 5 + " + smoothed +
                            " WHERE name = 'phi_peak_deg' AND task_id = (SELECT id FROM tasks WHERE "
                            "json_extract(params_json, '$.dt_factor') = 0.15 AND json_extract(params_json, '$.seed') = 2)";
  EXPECT_EQ(sqlite3_exec(db, raise.c_str(), nullptr, nullptr, nullptr), SQLITE_OK) << sqlite3_errmsg(db);
  EXPECT_EQ(sqlite3_changes(db), 1);
  sqlite3_close(db);
  const Result spiked = run_demcal(args, d.path.string());
  ASSERT_EQ(spiked.rc, 0) << spiked.err;
  EXPECT_NE(spiked.out.find("0.15*  "), std::string::npos) << spiked.out;
  EXPECT_NE(spiked.out.find("  spike 1\n"), std::string::npos) << spiked.out;
  EXPECT_NE(spiked.out.find("phi_peak rests on a spike of the walls' stress in 0.15 (the reference): 1 of 2 replica(s), "
                            "listed below"),
            std::string::npos)
      << spiked.out;
  EXPECT_NE(spiked.out.find(demcal::calibrate::spike_heading() + " (1):\n  dt=0.15 seed 2: phi_peak "),
            std::string::npos)
      << spiked.out;
  EXPECT_NE(slurp(d.file("f/fidelity-dt_recommendation.txt")).find("  dt=0.15 seed 2: phi_peak "), std::string::npos);
  EXPECT_NE(slurp(d.file("f/fidelity-dt.csv")).find(",1,\""), std::string::npos);  // peak_spikes of the 0.15 row
  EXPECT_NE(slurp(d.file("f/fidelity-dt_dt.dat")).find("\"0.15 (ref) (1/2 peak on a spike)\""), std::string::npos);

  // Judged by the running mean's peak instead: the same tasks, files of its own, and
  // the raised replica no longer moves the reference (its raw mean is 5/2 deg higher).
  std::vector<std::string> smoothed_args = args;
  smoothed_args.insert(smoothed_args.end(), {"--peak", "smoothed"});
  const std::string raw_recommendation = slurp(d.file("f/fidelity-dt_recommendation.txt"));
  const Result sm = run_demcal(smoothed_args, d.path.string());
  ASSERT_EQ(sm.rc, 0) << sm.err;
  EXPECT_NE(sm.out.find("6 tasks in s.db (6 reused, 0 run now)"), std::string::npos) << sm.out;
  EXPECT_NE(sm.out.find("phi_peak judged by the peak of its running mean"), std::string::npos) << sm.out;
  EXPECT_NE(sm.out.find("(judged here by the running mean's peak, which a spike of one or two rows moves by at most two fifths of its height)"),
            std::string::npos)
      << sm.out;
  EXPECT_NE(sm.out.find("recommended settings (fidelity, phi_peak by its running mean,"), std::string::npos) << sm.out;
  for (const char* f : {"fidelity-smoothed-peak-dt_dt.png", "fidelity-smoothed-peak-dt.csv",
                        "fidelity-smoothed-peak-dt_recommendation.txt"})
    EXPECT_TRUE(fs::exists(d.path / "f" / f)) << f;
  EXPECT_EQ(slurp(d.file("f/fidelity-dt_recommendation.txt")), raw_recommendation);  // the raw run's files kept
  const auto reference_mean = [&](const std::string& csv_name, const std::string& column) {
    std::istringstream in(slurp(d.file("f/" + csv_name)));
    std::string line, cell;
    std::getline(in, line);
    std::istringstream head(line);
    int col = -1;
    for (int i = 0; std::getline(head, cell, ','); ++i)
      if (cell == column) col = i;
    while (std::getline(in, line)) {
      if (line.rfind("dt,0.15,", 0) != 0) continue;
      std::istringstream row(line);
      for (int i = 0; std::getline(row, cell, ','); ++i)
        if (i == col) return std::stod(cell);
    }
    return std::nan("");
  };
  const double raw_ref = reference_mean("fidelity-dt.csv", "phi_peak_deg_mean");
  const double smoothed_ref = reference_mean("fidelity-smoothed-peak-dt.csv", "phi_peak_smoothed_deg_mean");
  EXPECT_NEAR(raw_ref - smoothed_ref, 2.5, 1e-3) << raw_ref << " " << smoothed_ref;
}

// Softer grains take longer steps: the knob sets kn, and ks, the preparation's wall
// speed and the dense preparation's load follow it (without them a soft sample's
// preparation blows up); the seed's stiffness is the baseline, its job the other
// knobs' baseline job.
TEST(CliStudy, FidelityStiffnessKnobSoftensTheGrainsAndWhatMustFollow) {
  TempDir d;
  const std::vector<std::string> args = {"study", "fidelity", "--quick", "--knobs", "stiffness", "--workers", "2",
                                         "--db", "s.db", "--out", "f"};
  const Result r = run_demcal(args, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err << r.out;
  EXPECT_NE(r.out.find("2 tasks in s.db (0 reused, 2 run now)"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("stiffness (kn):"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("stiffness 3e+07; 1 replica(s)"), std::string::npos) << r.out;
  const nlohmann::json soft = nlohmann::json::parse(slurp(d.file("f/jobs/study-fidelity-quick-stiffness-3e06.json")));
  EXPECT_EQ(soft["material"]["kn"].get<double>(), 3e6);
  EXPECT_EQ(soft["material"]["ks"].get<double>(), 2.7e6);
  EXPECT_EQ(soft["triaxial"]["prep_strain_rate"].get<double>(), 0.00632);  // 0.02 sqrt(1/10)
  EXPECT_EQ(soft["triaxial"]["prep_pressure_factor"].get<double>(), 10.0);  // kn/(100 p0 d_min) = 3000 kept
  const nlohmann::json seed = nlohmann::json::parse(slurp(d.file("f/jobs/study-fidelity-quick-stiffness-3e07.json")));
  EXPECT_FALSE(seed["triaxial"].contains("prep_strain_rate"));
  EXPECT_FALSE(seed["triaxial"].contains("prep_pressure_factor"));
  // The soft task's step is sqrt(10) times longer, and its shear that many times shorter.
  const Result q = run_demcal({"query", "--db", "s.db", "--metrics", "dt,shear.steps", "--format", "csv"}, d.path.string());
  ASSERT_EQ(q.rc, 0) << q.err;
  std::istringstream in(q.out);
  std::string line, cell;
  std::getline(in, line);
  std::vector<std::string> head;
  for (std::istringstream h(line); std::getline(h, cell, ',');) head.push_back(cell);
  std::map<double, std::pair<double, double>> by_kn;  // kn: dt, shear steps
  while (std::getline(in, line)) {
    std::map<std::string, std::string> row;
    std::istringstream cells(line);
    for (std::size_t i = 0; i < head.size() && std::getline(cells, cell, ','); ++i) row[head[i]] = cell;
    by_kn[std::stod(row["kn"])] = {std::stod(row["dt"]), std::stod(row["shear.steps"])};
  }
  ASSERT_EQ(by_kn.size(), 2u) << q.out;
  EXPECT_NEAR(by_kn[3e6].first / by_kn[3e7].first, std::sqrt(10.0), 1e-6);
  EXPECT_NEAR(by_kn[3e7].second / by_kn[3e6].second, std::sqrt(10.0), 0.01);
  // kn names the knob too; the reference may be set by it; a rerun reuses both tasks.
  std::vector<std::string> by_name = args;
  by_name[4] = "kn";
  const Result again = run_demcal(by_name, d.path.string());
  ASSERT_EQ(again.rc, 0) << again.err;
  EXPECT_NE(again.out.find("2 tasks in s.db (2 reused, 0 run now)"), std::string::npos) << again.out;
}

// Every knob's table holds the baseline's tasks: the warnings are counted per task,
// once, as the task count is (7 tasks, 2 of them failing by design).
TEST(CliStudy, FidelityCountsEachWarnedTaskOnce) {
  TempDir d;
  const Result r = run_demcal({"study", "fidelity", "--quick", "--workers", "2", "--db", "s.db", "--out", "f"},
                              d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err << r.out;
  EXPECT_NE(r.out.find("7 tasks in s.db"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("failed tasks (2)"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("warnings: 5 of the 5 finished tasks carry warnings"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("--job JOB lists them, JOB one of study-fidelity-quick-density, study-fidelity-quick-dt"),
            std::string::npos)
      << r.out;
}

TEST(CliStudy, FidelityUnknownKnobIsBadInput) {
  TempDir d;
  Result r = run_demcal({"study", "fidelity", "--quick", "--knobs", "particles,partcles"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("unknown knob \"partcles\""), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("particles, rate, dt, density"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(d.path / "demcal.db"));  // nothing written
  r = run_demcal({"study", "repose-fidelity", "--knobs", "slab"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("unknown knob \"slab\""), std::string::npos) << r.err;
  r = run_demcal({"study", "fidelity", "--reference", "rate"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--reference"), std::string::npos) << r.err;
  r = run_demcal({"study", "timestep", "--knobs", "dt"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  // --peak where there is no peak strength, even as its default raw: named, refused
  // before anything is written.
  for (const char* study : {"repose-fidelity", "timestep", "grazing"})
    for (const char* peak : {"smoothed", "raw"}) {
      r = run_demcal({"study", study, "--quick", "--peak", peak, "--out", "peak-out"}, d.path.string());
      EXPECT_EQ(r.rc, 2) << study << " " << peak;
      EXPECT_NE(r.err.find("--peak: study " + std::string(study) + " has no peak strength to judge"), std::string::npos)
          << r.err;
      EXPECT_FALSE(fs::exists(d.path / "peak-out")) << study;
      EXPECT_FALSE(fs::exists(d.path / "demcal.db")) << study;
    }
  r = run_demcal({"study", "fidelity", "--quick", "--peak", "median"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--peak"), std::string::npos) << r.err;
  // A reference the scene refuses is named as the user wrote it, not as the grid path
  // of the study's own job, and refused before the database exists.
  r = run_demcal({"study", "fidelity", "--reference", "dt=1e9"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--reference: dt = 1e+09: must be in (0, 10]"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(d.path / "demcal.db"));
  // References that would be resolved silently: two for one knob (under one name or
  // two), and one for a knob the study leaves out.
  for (const std::vector<std::string>& refs :
       {std::vector<std::string>{"particles=150", "particles=300"}, {"rate=1e-2", "strain_rate=3e-3"}}) {
    std::vector<std::string> args = {"study", "fidelity", "--quick"};
    for (const auto& x : refs) args.insert(args.end(), {"--reference", x});
    r = run_demcal(args, d.path.string());
    EXPECT_EQ(r.rc, 2) << refs[1];
    EXPECT_NE(r.err.find("--reference"), std::string::npos) << r.err;
  }
  r = run_demcal({"study", "fidelity", "--quick", "--knobs", "particles", "--reference", "density=1e30"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("density is not among the knobs this study varies"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(d.path / "demcal.db"));
  EXPECT_FALSE(fs::exists(d.path / "demcal-out"));  // nor a folder
}
