#include "cli_util.hpp"
#include "dist_util.hpp"

#include "jobs/hdf5_writer.hpp"
#include "jobs/job_spec.hpp"
#include "jobs/worker.hpp"
#include "jobs/xdmf_writer.hpp"

#include <H5Cpp.h>

#include <fstream>
#include <regex>

using namespace demcal::test;
using nlohmann::json;

TEST(Cli, HelpOnEverySubcommand) {
  TempDir d;
  for (const char* cmd : {"validate", "run", "status", "query", "plot", "map", "envelope", "fit", "merge", "slurm",
                          "study"}) {
    const Result r = run_demcal({cmd, "--help"}, d.path.string());
    EXPECT_EQ(r.rc, 0) << cmd;
    EXPECT_NE(r.out.find("Usage"), std::string::npos) << cmd << r.out;
  }
  EXPECT_EQ(run_demcal({}, d.path.string()).rc, 2);
  EXPECT_EQ(run_demcal({"run"}, d.path.string()).rc, 2);
  EXPECT_EQ(run_demcal({"frobnicate"}, d.path.string()).rc, 2);
}

TEST(Cli, ValidatePrintsCountAndFirstTask) {
  TempDir d;
  const Result r = run_demcal({"validate", std::string(DEMCAL_EXAMPLES_DIR) + "/collision.json"}, d.path.string());
  EXPECT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.out.find("4 task(s)"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("\"dt_factor\": 0.05"), std::string::npos) << r.out;
  EXPECT_TRUE(fs::is_empty(d.path / "out.stderr"));
  // What the job will cost: 500 grains x 20,000 steps a task (the example's), 4 tasks.
  EXPECT_NE(r.out.find("work: the collision run is 1e+07 grain-steps a task, 4e+07 in all: under a minute of one core (divide by --workers)"), std::string::npos) << r.out;
  // A triaxial job: the shear's steps are forecast, the preparation's are not.
  const Result t = run_demcal({"validate", std::string(DEMCAL_EXAMPLES_DIR) + "/quickstart.json"}, d.path.string());
  EXPECT_NE(t.out.find("work: the shear is "), std::string::npos) << t.out;
  EXPECT_NE(t.out.find("the preparation adds"), std::string::npos) << t.out;
  // Where each flat name goes in a job file: a material key is refused in the
  // scene's section, and d_min is "diameter.min" in the material's.
  EXPECT_NE(t.out.find("in a job file:\n  \"material\": {kn, ks, density, b, theta_deg, eta, diameter.min (d_min), "
                       "diameter.max (d_max)}\n  \"triaxial\": {particles, packing, confining_kpa,"),
            std::string::npos)
      << t.out;
  EXPECT_NE(t.out.find("\n  top level: seed\n"), std::string::npos) << t.out;
}

TEST(Cli, ValidateRejectsBadJobsNamingTheField) {
  TempDir d;
  write(d.file("bad.json"), R"({"name": "b", "scene": "collision", "collision": {"partcles": 10}})");
  Result r = run_demcal({"validate", "bad.json"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("collision.partcles"), std::string::npos) << r.err;
  // A name without its unit is taken for it, not for the nearest typo ("eta").
  write(d.file("theta.json"), R"({"name": "t", "scene": "triaxial", "material": {"theta": 30}})");
  r = run_demcal({"validate", "theta.json"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("material.theta: unknown key (did you mean \"theta_deg\"?)"), std::string::npos) << r.err;
  write(d.file("unknown.json"), R"({"name": "u", "scene": "triaxal"})");
  r = run_demcal({"validate", "unknown.json"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("scene"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("triaxal"), std::string::npos) << r.err;
  r = run_demcal({"validate", "missing.json"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("missing.json"), std::string::npos) << r.err;
}

TEST(Cli, RunForecastsTheWorkOfTheTasksItWillRun) {
  TempDir d;
  write(d.file("j.json"), collision_job("work", {0.05, 0.1}));  // 30 grains x 400 steps a task
  Result r = run_demcal({"run", "j.json"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.err.find("work of the 2 task(s) to run: the collision run is 1.2e+04 grain-steps a task, 2.4e+04 in all"),
            std::string::npos) << r.err;
  r = run_demcal({"run", "j.json"}, d.path.string());  // all reused: nothing to forecast
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_EQ(r.err.find("work of"), std::string::npos) << r.err;
}

TEST(Cli, ForecastsAtTheSpeedOfTheDatabasesDoneTasks) {
  TempDir d;
  write(d.file("j.json"), collision_job("work", {0.05, 0.1}));
  ASSERT_EQ(run_demcal({"run", "j.json"}, d.path.string()).rc, 0);
  // Another job of the scene, validated against what the first one's tasks cost.
  write(d.file("k.json"), collision_job("more", {0.02, 0.03, 0.04}));
  Result r = run_demcal({"validate", "k.json", "--db", "demcal.db"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.out.find("at the speed of the last 2 done collision task(s) in this database (their CPU time"),
            std::string::npos) << r.out;
  // Tasks done in the database already are reused by a run: validate forecasts the rest.
  r = run_demcal({"validate", "j.json", "--db", "demcal.db"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.out.find("work: of the 2 task(s), demcal.db holds 2 done (demcal run reuses them); nothing to run"),
            std::string::npos) << r.out;
  EXPECT_EQ(r.out.find("grain-steps"), std::string::npos) << r.out;
  write(d.file("m.json"), collision_job("mix", {0.05, 0.06, 0.07}));  // none shared with k.json
  r = run_demcal({"validate", "m.json", "--db", "demcal.db"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.out.find("work: of the 3 task(s), demcal.db holds 1 done (demcal run reuses them); the other 2 below"),
            std::string::npos) << r.out;
  {  // One of them failed there: a run leaves it unless asked to retry.
    const demcal::jobs::Job mix = demcal::jobs::load_job_file(d.file("m.json"));
    demcal::db::Store store(d.file("demcal.db"));
    std::vector<demcal::db::NewTask> tasks;
    for (const auto& t : mix.tasks) tasks.push_back({t.key, mix.scene, t.params.dump()});
    store.put_job(mix.name, mix.spec.dump(), tasks);
    const auto rows = store.tasks(mix.name);
    ASSERT_TRUE(store.claim(rows[1].id, "w"));
    demcal::db::Outcome failed;
    failed.status = "failed";
    failed.error = "synthetic";
    failed.metrics = {{"cpu_s", 1.0}};
    ASSERT_TRUE(store.finish(rows[1].id, "w", failed));
    ASSERT_EQ(store.reset_failed(*store.find_job(mix.name)), 1);
    EXPECT_TRUE(store.metrics(rows[1].id).empty()) << "a retried task shows no old run's metrics";
    ASSERT_TRUE(store.claim(rows[1].id, "w"));
    ASSERT_TRUE(store.finish(rows[1].id, "w", failed));
  }
  r = run_demcal({"validate", "m.json", "--db", "demcal.db"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.out.find("work: of the 3 task(s), demcal.db holds 1 done (demcal run reuses them), 1 failed (run leaves "
                       "them unless --retry-failed); the other 1 below"),
            std::string::npos) << r.out;
  r = run_demcal({"validate", "k.json", "--db", "missing.db"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--db: no database at missing.db"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(d.file("missing.db")));
  // Its tasks recorded but not run: status says how long they will take.
  const demcal::jobs::Job more = demcal::jobs::load_job_file(d.file("k.json"));
  {
    demcal::db::Store store(d.file("demcal.db"));
    std::vector<demcal::db::NewTask> tasks;
    for (const auto& t : more.tasks) tasks.push_back({t.key, more.scene, t.params.dump()});
    store.put_job(more.name, more.spec.dump(), tasks);
  }
  r = run_demcal({"status"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.out.find("more: 3 task(s) to go: under a minute of one core; at the speed of the last 2 done collision"),
            std::string::npos) << r.out;
  EXPECT_EQ(r.out.find("work: "), std::string::npos) << "the finished job has nothing to go\n" << r.out;
}

TEST(Cli, InvalidJobWritesNothing) {
  TempDir d;
  write(d.file("bad.json"), R"({"name": "b", "scene": "collision", "material": {"theta_deg": 90}})");
  const Result r = run_demcal({"run", "bad.json", "--db", "x.db"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("material.theta_deg"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(d.file("x.db")));
  EXPECT_FALSE(fs::exists(d.file("demcal-out")));
}

TEST(Cli, RunQueryStatusAndResume) {
  TempDir d;
  write(d.file("j.json"), collision_job("small", {0.05, 0.1, 0.2}));
  Result r = run_demcal({"run", "j.json", "--workers", "2"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.out.find("drift_per_million_steps"), std::string::npos) << r.out;
  // The table shows the scene's headline metrics and says how to get the rest.
  EXPECT_EQ(r.out.find("energy_initial"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("more metrics per task: demcal query --db demcal.db --job small --metrics all"),
            std::string::npos)
      << r.out;
  Result all = run_demcal({"query", "--metrics", "all"}, d.path.string());
  ASSERT_EQ(all.rc, 0) << all.err;
  EXPECT_NE(all.out.find("energy_initial"), std::string::npos) << all.out;
  EXPECT_EQ(all.out.find("more metrics"), std::string::npos) << all.out;
  const auto before = tasks_of(d.file("demcal.db"), "small");
  ASSERT_EQ(before.size(), 3u);
  for (const auto& t : before) {
    EXPECT_EQ(t.status, "done");
    EXPECT_TRUE(fs::exists(d.path / "demcal-out" / "small" / demcal::jobs::task_file_name(t.id, t.key)));
  }

  r = run_demcal({"query", "--job", "small", "--where", "dt_factor=0.1", "--format", "json"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  const json rows = json::parse(r.out);
  ASSERT_EQ(rows.size(), 1u);
  EXPECT_DOUBLE_EQ(rows[0]["params"]["dt_factor"].get<double>(), 0.1);
  EXPECT_TRUE(rows[0]["metrics"]["drift_per_million_steps"].is_number());
  // Where the task's series are: the file a user opens.
  ASSERT_TRUE(rows[0].contains("hdf5")) << rows[0].dump();
  EXPECT_TRUE(fs::exists(rows[0]["hdf5"].get<std::string>()));

  r = run_demcal({"query", "--format", "csv", "--metrics", "dt,drift_per_million_steps"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_EQ(std::count(r.out.begin(), r.out.end(), '\n'), 4);
  EXPECT_NE(r.out.find(",dt,drift_per_million_steps,"), std::string::npos) << r.out;

  EXPECT_EQ(run_demcal({"query", "--where", "nosuch=1"}, d.path.string()).rc, 2);
  r = run_demcal({"query", "--metrics", "dt,nosuch"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("no task stores a metric \"nosuch\""), std::string::npos) << r.err;
  r = run_demcal({"query", "--metrics", "drift_per_million"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("did you mean \"drift_per_million_steps\"?"), std::string::npos) << r.err;
  EXPECT_EQ(run_demcal({"query", "--where", "novalue"}, d.path.string()).rc, 2);
  // Values no task could match are typos, not empty answers.
  r = run_demcal({"query", "--where", "status=finished"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("status is one of"), std::string::npos) << r.err;
  r = run_demcal({"query", "--where", "dt_factor=abc"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("dt_factor is a number"), std::string::npos) << r.err;
  r = run_demcal({"query", "--where", "task=abc"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("task is a task id"), std::string::npos) << r.err;
  r = run_demcal({"query", "--where", "dt_factor=0.3"}, d.path.string());
  EXPECT_EQ(r.rc, 0);
  // Which filter matched nothing, and what its key takes.
  EXPECT_NE(r.err.find("no task matches the --where filters: dt_factor=0.3 matches no task; dt_factor takes 0.05, 0.1"),
            std::string::npos) << r.err;
  r = run_demcal({"query", "--where", "dt_factor=0.1", "--where", "dt_factor=0.05"}, d.path.string());
  EXPECT_NE(r.err.find("no task matches them all (filters on one key are not alternatives)"), std::string::npos) << r.err;
  r = run_demcal({"query", "--where", "sample=20"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("no task has a parameter \"sample\" (did you mean \"sample_every\"?)"), std::string::npos) << r.err;
  // One row varies nothing: the table shows no parameter columns (JSON and CSV keep them).
  r = run_demcal({"query", "--where", "dt_factor=0.1"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_EQ(r.out.find("sample_every"), std::string::npos) << r.out;
  EXPECT_EQ(run_demcal({"query", "--format", "xml"}, d.path.string()).rc, 2);

  r = run_demcal({"status"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.out.find("small"), std::string::npos);
  EXPECT_EQ(run_demcal({"status", "--job", "nope"}, d.path.string()).rc, 2);

  // Running again reuses everything: nothing is re-run.
  r = run_demcal({"run", "j.json"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.err.find("3 of 3 task(s) already done"), std::string::npos) << r.err;
  const auto after = tasks_of(d.file("demcal.db"), "small");
  for (std::size_t i = 0; i < after.size(); ++i) {
    EXPECT_EQ(after[i].started_at, before[i].started_at);
    EXPECT_EQ(after[i].attempts, 1);
  }
}

TEST(Cli, StatusWithoutDatabaseIsBadInput) {
  TempDir d;
  const Result r = run_demcal({"status", "--db", "none.db"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_FALSE(fs::exists(d.file("none.db")));
}

TEST(Cli, ForeignDatabasesAreRejectedUntouched) {
  TempDir d;
  write(d.file("j.json"), collision_job("small", {0.1}));
  write(d.file("notes.db"), "plain text, not SQLite\n");
  Result r = run_demcal({"run", "j.json", "--db", "notes.db"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("not a SQLite database"), std::string::npos) << r.err;
  EXPECT_EQ(slurp(d.file("notes.db")), "plain text, not SQLite\n");
  r = run_demcal({"status", "--db", "notes.db"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_FALSE(fs::exists(d.file("demcal-out")));
}

TEST(Cli, EmptyDatabaseFileIsBadInputAndLeftEmpty) {
  TempDir d;
  write(d.file("empty.db"), "");
  for (const std::vector<std::string>& args :
       {std::vector<std::string>{"status", "--db", "empty.db"}, {"query", "--db", "empty.db"},
        {"fit", "--db", "empty.db", "--target", "phi_peak=41"}}) {
    const Result r = run_demcal(args, d.path.string());
    EXPECT_EQ(r.rc, 2) << args[0] << ": " << r.err;
    EXPECT_NE(r.err.find("holds no demcal results"), std::string::npos) << args[0] << ": " << r.err;
  }
  EXPECT_EQ(fs::file_size(d.file("empty.db")), 0u);
}

TEST(Cli, MissingJobFileAndDatabaseDirectorySayWhy) {
  TempDir d;
  Result r = run_demcal({"run", "nosuch.json"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("nosuch.json: no such file"), std::string::npos) << r.err;
  fs::create_directories(d.path / "adir");
  r = run_demcal({"validate", "adir"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("it is a directory"), std::string::npos) << r.err;
  write(d.file("j.json"), collision_job("small", {0.1}));
  r = run_demcal({"run", "j.json", "--db", "nope/x.db"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("does not exist"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(d.path / "nope"));
}

TEST(Cli, QueryHeadersAreUniqueAndFitSaysNoDataFirst) {
  // The collision scene has a parameter and a metric both called `steps`.
  TempDir d;
  write(d.file("j.json"), collision_job("small", {0.05, 0.1}));
  ASSERT_EQ(run_demcal({"run", "j.json"}, d.path.string()).rc, 0);
  Result r = run_demcal({"query", "--format", "csv"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  const std::string header = r.out.substr(0, r.out.find('\n'));
  EXPECT_NE(header.find(",steps,"), std::string::npos) << header;
  EXPECT_NE(header.find(",metric.steps,"), std::string::npos) << header;
  // Two dt factors vary, but the job holds no phi_peak at all: that is the error.
  r = run_demcal({"fit", "--target", "phi_peak=41.4"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("no data"), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find("--where"), std::string::npos) << r.err;
}

// A key a task's parameters leave out at its default is --where'd at that default:
// size_distribution=uniform matched no task, though the README calls writing it out
// the same as leaving it out. And -0.0 is 0: the same task, reused.
TEST(Cli, AWhereOnAParameterAtItsDefaultMatchesTheTasksThatLeftItOut) {
  TempDir d;
  nlohmann::json j = nlohmann::json::parse(collision_job("sizes", {0.1}));
  j["grid"]["size_distribution"] = {"uniform", "uniform_mass"};
  write(d.file("j.json"), j.dump());
  ASSERT_EQ(run_demcal({"run", "j.json", "--workers", "1"}, d.path.string()).rc, 0);
  Result r = run_demcal({"query", "--where", "size_distribution=uniform", "--format", "csv"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_EQ(std::count(r.out.begin(), r.out.end(), '\n'), 2) << r.out;  // the header and one task
  EXPECT_EQ(r.out.find("\n1,sizes,done,"), r.out.find('\n')) << r.out;
  // Unfiltered, the column says what the task that left it out ran with (columns in
  // key order, as JSON's params).
  r = run_demcal({"query", "--format", "csv"}, d.path.string());
  EXPECT_NE(r.out.find(",1,uniform,0.2,"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find(",1,uniform_mass,0.2,"), std::string::npos) << r.out;
  r = run_demcal({"query", "--where", "size_distribution=uniform_mass", "--format", "csv"}, d.path.string());
  EXPECT_EQ(std::count(r.out.begin(), r.out.end(), '\n'), 2) << r.out;
  // A database of only default tasks: the key is still known.
  j["name"] = "plain";
  j["grid"].erase("size_distribution");
  write(d.file("p.json"), j.dump());
  ASSERT_EQ(run_demcal({"run", "p.json", "--db", "p.db", "--workers", "1"}, d.path.string()).rc, 0);
  r = run_demcal({"query", "--db", "p.db", "--where", "size_distribution=uniform"}, d.path.string());
  EXPECT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.out.find("plain"), std::string::npos) << r.out;
  // JSON gives every parameter the task ran with, the defaults it left out too; a
  // misspelt key is matched against those as well.
  r = run_demcal({"query", "--db", "p.db", "--format", "json"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_EQ(nlohmann::json::parse(r.out).at(0).at("params").value("size_distribution", ""), "uniform") << r.out;
  r = run_demcal({"query", "--db", "p.db", "--where", "size_distributon=uniform"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("(did you mean \"size_distribution\"?)"), std::string::npos) << r.err;
  // -0.0 written for eta is eta = 0: the task is reused, not run again.
  j["material"]["eta"] = 0;
  std::string text = j.dump();
  const auto at = text.find("\"eta\":0");
  ASSERT_NE(at, std::string::npos) << text;
  text.replace(at, 7, "\"eta\":-0.0");
  write(d.file("m.json"), text);
  r = run_demcal({"run", "m.json", "--db", "p.db", "--workers", "1"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.err.find("job plain: 1 done (1 reused)"), std::string::npos) << text << r.err;
  EXPECT_EQ(tasks_of(d.file("p.db")).size(), 1u);
}

TEST(Cli, GradingCurvesAreAGridAxisAndAWhereValue) {
  TempDir d;
  const nlohmann::json fine = {{"d", {0.0006, 0.001, 0.002}}, {"percent_finer", {0, 40, 100}}};
  const nlohmann::json coarse = {{"d", {0.0006, 0.001, 0.002}}, {"percent_finer", {0, 10, 100}}};
  nlohmann::json j = nlohmann::json::parse(collision_job("curves", {0.1}));
  j["material"]["diameter"] = nlohmann::json::object();
  j["grid"] = {{"grading", {fine, coarse}}};
  write(d.file("j.json"), j.dump());
  Result r = run_demcal({"run", "j.json"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  // Written as the job wrote it (integers), matched to the stored reals.
  r = run_demcal({"query", "--format", "json", "--where", "grading=" + coarse.dump()}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  const nlohmann::json rows = nlohmann::json::parse(r.out);
  ASSERT_EQ(rows.size(), 1u) << r.out;
  EXPECT_EQ(rows[0]["params"]["grading"]["percent_finer"][1], 10.0);
  EXPECT_EQ(rows[0]["params"]["d_min"], 0.0006);
  // A table for reading names each curve and prints it once below, ready for --where.
  r = run_demcal({"query"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.out.find("  grading #2  "), std::string::npos) << r.out;
  EXPECT_EQ(r.out.find("grading #3"), std::string::npos) << r.out;
  const std::string footnote = "grading #2 (task 2): grading=" + nlohmann::json::parse(rows[0]["params"]["grading"].dump()).dump();
  EXPECT_NE(r.out.find(footnote), std::string::npos) << footnote << "\n" << r.out;
  const std::string where = r.out.substr(r.out.find("grading #2 (task 2): ") + 21);
  r = run_demcal({"query", "--where", where.substr(0, where.find('\n')), "--format", "csv"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_EQ(std::count(r.out.begin(), r.out.end(), '\n'), 2) << "the header and task 2\n" << r.out;
  r = run_demcal({"query", "--where", "grading={\"d\": [0.0006, 0.002], \"percent_finer\": [0, 100]}"}, d.path.string());
  EXPECT_NE((r.out + r.err).find("no task matches"), std::string::npos) << r.out << r.err;
  r = run_demcal({"query", "--where", "grading={d: [0.0006]}"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--where: grading is a list or object"), std::string::npos) << r.err;
}

TEST(Cli, SnapshotsAreWrittenInTheH5PartLayoutOnlyWhenAsked) {
  TempDir d;
  json j = json::parse(collision_job("snap", {0.1}));
  j["snapshots"] = true;
  write(d.file("snap.json"), j.dump());
  write(d.file("plain.json"), collision_job("plain", {0.05}));
  ASSERT_EQ(run_demcal({"run", "snap.json"}, d.path.string()).rc, 0);
  ASSERT_EQ(run_demcal({"run", "plain.json"}, d.path.string()).rc, 0);
  const auto snap = tasks_of(d.file("demcal.db"), "snap");
  const auto plain = tasks_of(d.file("demcal.db"), "plain");
  ASSERT_EQ(snap.size(), 1u);
  ASSERT_EQ(plain.size(), 1u);
  const std::string snap_file = (d.path / "demcal-out" / "snap" / demcal::jobs::task_file_name(snap[0].id, snap[0].key)).string();
  EXPECT_EQ(demcal::jobs::read_task_key(snap_file), snap[0].key);  // the file says whose it is
  H5::H5File f(snap_file, H5F_ACC_RDONLY);
  for (const auto& [step, label] : {std::pair<const char*, const char*>{"Step#0", "initial"}, {"Step#1", "final"}}) {
    ASSERT_TRUE(f.nameExists(step)) << step;
    H5::Group g = f.openGroup(step);
    std::string got;
    H5::Attribute a = g.openAttribute("label");
    a.read(a.getStrType(), got);
    EXPECT_EQ(got, label);
    EXPECT_TRUE(g.attrExists("TimeValue"));
    for (const char* col : {"x", "y", "z", "radius", "vx", "vy", "vz"}) {
      hsize_t n = 0;
      g.openDataSet(col).getSpace().getSimpleExtentDims(&n);
      EXPECT_EQ(n, 30u) << step << "/" << col;  // every grain of the 30-grain job
    }
  }
  EXPECT_FALSE(f.nameExists("Step#2"));
  // Self-describing: the scene at the root, a unit on every dataset.
  auto text = [](const H5::H5Object& o, const char* name) {
    std::string v;
    H5::Attribute a = o.openAttribute(name);
    a.read(a.getStrType(), v);
    return v;
  };
  EXPECT_EQ(text(f, "scene"), "collision");
  EXPECT_EQ(f.openAttribute("physics_version").getTypeClass(), H5T_INTEGER);
  std::int64_t id = 0;
  f.openAttribute("task_id").read(H5::PredType::NATIVE_INT64, &id);
  EXPECT_EQ(id, snap[0].id);
  EXPECT_EQ(text(f.openGroup("Step#1"), "TimeValue_units"), "s");
  EXPECT_EQ(text(f.openDataSet("series/energy/time"), "units"), "s");
  EXPECT_EQ(text(f.openDataSet("series/energy/kinetic"), "units"), "J");
  EXPECT_EQ(text(f.openDataSet("Step#0/vx"), "units"), "m/s");
  EXPECT_EQ(text(f.openDataSet("Step#1/wz"), "units"), "rad/s");  // spins: eta is half of what is calibrated
  EXPECT_TRUE(f.nameExists("Step#1/fixed"));
  EXPECT_EQ(text(f, "status"), "done");
  H5::H5File p((d.path / "demcal-out" / "plain" / demcal::jobs::task_file_name(plain[0].id, plain[0].key)).string(), H5F_ACC_RDONLY);
  EXPECT_FALSE(p.nameExists("Step#0"));
  EXPECT_TRUE(p.nameExists("series"));
  p.close();
  // Snapshots asked for later: the plain job's task is run again (not reused from a
  // file without any), and its new file holds them.
  json again = json::parse(collision_job("plain", {0.05}));
  again["snapshots"] = true;
  write(d.file("plain-snap.json"), again.dump());
  const Result r = run_demcal({"run", "plain-snap.json"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.err.find("1 done (0 reused)"), std::string::npos) << r.err;
  const auto plain2 = tasks_of(d.file("demcal.db"), "plain");
  ASSERT_EQ(plain2.size(), 1u);
  EXPECT_NE(plain2[0].key, plain[0].key);
  H5::H5File q((d.path / "demcal-out" / "plain" / demcal::jobs::task_file_name(plain2[0].id, plain2[0].key)).string(),
               H5F_ACC_RDONLY);
  EXPECT_TRUE(q.nameExists("Step#0"));
  EXPECT_FALSE(fs::exists(demcal::jobs::xdmf_path_for(
      (d.path / "demcal-out" / "plain" / demcal::jobs::task_file_name(plain[0].id, plain[0].key)).string())));
}

// Runs a one-task collision job `name` with snapshots in d; its HDF5 and .xmf paths.
std::pair<fs::path, std::string> run_with_snapshots(const TempDir& d, const std::string& name) {
  json j = json::parse(collision_job(name, {0.1}));
  j["snapshots"] = true;
  write(d.file(name + ".json"), j.dump());
  EXPECT_EQ(run_demcal({"run", name + ".json"}, d.path.string()).rc, 0);
  const auto task = tasks_of(d.file("demcal.db"), name).at(0);
  const fs::path h5 = d.path / "demcal-out" / name / demcal::jobs::task_file_name(task.id, task.key);
  return {h5, demcal::jobs::xdmf_path_for(h5.string())};
}

// The .xmf is a viewing aid: when it cannot be written the task still finishes with its
// metrics and HDF5 file, and says why there is no .xmf.
TEST(Cli, AnXdmfThatCannotBeWrittenIsAWarningNotALostTask) {
  TempDir d;
  const auto [h5, xmf] = run_with_snapshots(d, "xw");
  // The same task from scratch, with a folder (not empty) where the .xmf goes.
  fs::remove(d.file("demcal.db"));
  fs::remove_all(d.path / "demcal-out");
  fs::create_directories(xmf + "/in-the-way");
  const Result r = run_demcal({"run", "xw.json"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  const auto again = tasks_of(d.file("demcal.db"), "xw").at(0);
  EXPECT_EQ(again.status, "done");
  EXPECT_NE(again.error.find("cannot move the Xdmf file into place at " + xmf), std::string::npos) << again.error;
  EXPECT_TRUE(fs::exists(h5));
  EXPECT_TRUE(fs::is_directory(xmf)) << "the folder in the way is left alone";
  for (const auto& e : fs::directory_iterator(fs::path(xmf).parent_path()))
    EXPECT_EQ(e.path().string().find(".part"), std::string::npos) << "left behind: " << e.path();
  const Result q = run_demcal({"query", "--job", "xw", "--format", "json"}, d.path.string());
  ASSERT_EQ(q.rc, 0) << q.err;
  const json row = json::parse(q.out).at(0);
  EXPECT_FALSE(row.at("metrics").empty());
  EXPECT_FALSE(row.contains("xdmf"));
}

// ParaView's Xdmf reader opens the snapshots through the .xmf beside the task's file:
// every dataset it names must exist in that file with the length it states, one grid
// per snapshot at the snapshot's time, velocity and spin as 3-vectors.
TEST(Cli, SnapshotsAreDescribedForParaViewByAnXdmfFileThatMatchesTheHdf5) {
  TempDir d;
  const auto [h5, xmf] = run_with_snapshots(d, "xmf");
  ASSERT_TRUE(fs::exists(xmf));
  const Result q = run_demcal({"query", "--job", "xmf", "--format", "json"}, d.path.string());
  ASSERT_EQ(q.rc, 0) << q.err;
  EXPECT_EQ(fs::path(json::parse(q.out).at(0).at("xdmf").get<std::string>()), fs::path(xmf));
  std::ifstream in(xmf);
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  H5::H5File f(h5.string(), H5F_ACC_RDONLY);
  // <DataItem Dimensions="N" ...>FILE:/GROUP/DATASET</DataItem>
  const std::regex item(R"re(<DataItem Dimensions="(\d+)"[^>]*Format="HDF">([^<:]+):([^<]+)</DataItem>)re");
  int items = 0;
  for (auto it = std::sregex_iterator(text.begin(), text.end(), item); it != std::sregex_iterator(); ++it, ++items) {
    EXPECT_EQ((*it)[2].str(), h5.filename().string());  // relative: the pair moves together
    const std::string path = (*it)[3].str();
    ASSERT_TRUE(f.nameExists(path)) << path;
    hsize_t n = 0;
    f.openDataSet(path).getSpace().getSimpleExtentDims(&n);
    EXPECT_EQ(std::to_string(n), (*it)[1].str()) << path;
  }
  EXPECT_EQ(items, 2 * 11);  // two snapshots, x y z radius vx vy vz wx wy wz fixed
  const std::regex grid(R"re(<Grid Name="([^"]+)" GridType="Uniform">\s*<Time Value="([^"]+)"/>)re");
  std::vector<std::pair<std::string, double>> grids;
  for (auto it = std::sregex_iterator(text.begin(), text.end(), grid); it != std::sregex_iterator(); ++it)
    grids.emplace_back((*it)[1].str(), std::stod((*it)[2].str()));
  ASSERT_EQ(grids.size(), 2u);
  for (std::size_t s = 0; s < grids.size(); ++s) {
    H5::Group g = f.openGroup(demcal::jobs::snapshot_group(s));
    double t = -1;
    g.openAttribute("TimeValue").read(H5::PredType::NATIVE_DOUBLE, &t);
    EXPECT_EQ(grids[s].second, t);
    EXPECT_EQ(grids[s].first, s == 0 ? "initial" : "final");
  }
  EXPECT_GT(grids[1].second, grids[0].second);
  for (const char* v : {"velocity", "spin"})
    EXPECT_NE(text.find(std::string("<Attribute Name=\"") + v + "\" AttributeType=\"Vector\""), std::string::npos) << v;
  EXPECT_NE(text.find("Function=\"JOIN($0, $1, $2)\" Dimensions=\"30 3\""), std::string::npos);
}

TEST(Cli, PlotDrawsPngAndSvg) {
  TempDir d;
  write(d.file("j.json"), collision_job("plot", {0.1}));
  ASSERT_EQ(run_demcal({"run", "j.json"}, d.path.string()).rc, 0);
  const auto task = tasks_of(d.file("demcal.db"))[0];
  const auto id = std::to_string(task.id);
  const fs::path file = d.path / "demcal-out" / "plot" / demcal::jobs::task_file_name(task.id, task.key);
  Result r = run_demcal({"plot", id, "--series", "energy", "--x", "step", "--y", "total,kinetic", "--out", "e.png"},
                    d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_GT(fs::file_size(d.file("e.png")), 1000u);
  r = run_demcal({"plot", id, "--series", "energy", "--x", "time", "--y", "total", "--out", "e.svg"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(slurp(d.file("e.svg")).find("<svg"), std::string::npos);
  // Columns in two units: each axis labelled with its unit, the second on y2.
  r = run_demcal({"plot", id, "--series", "energy", "--x", "step", "--y", "total,time", "--out", "u.svg"},
                 d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  const std::string svg = slurp(d.file("u.svg"));
  EXPECT_NE(svg.find("total [J]"), std::string::npos);
  EXPECT_NE(svg.find("time [s]"), std::string::npos);
  r = run_demcal({"plot", id, "--series", "energy", "--x", "step", "--y", "nope", "--out", "e.png"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("nope"), std::string::npos);
  // The scene's own series draw with their usual columns into taskID-SERIES.png.
  r = run_demcal({"plot", id, "--series", "energy"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_GT(fs::file_size(d.file("task" + id + "-energy.png")), 1000u);
  EXPECT_NE(r.out.find("task" + id + "-energy.png"), std::string::npos) << r.out;
  // A series the task does not have is named as the fault, with those it has,
  // whether or not the columns are given (it used to ask for --x, then --y).
  for (const std::vector<std::string>& cols : {std::vector<std::string>{}, {"--x", "x"}, {"--x", "x", "--y", "h"}}) {
    std::vector<std::string> args = {"plot", id, "--series", "profile"};
    args.insert(args.end(), cols.begin(), cols.end());
    r = run_demcal(args, d.path.string());
    EXPECT_EQ(r.rc, 2);
    EXPECT_NE(r.err.find("--series: "), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("no series \"profile\""), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("energy"), std::string::npos) << r.err;
  }
  r = run_demcal({"plot", "999", "--series", "energy", "--x", "step", "--y", "total", "--out", "e.png"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  // An id past int64 is refused as typed, not clamped to another id; so are 0 and signs.
  for (const char* bad : {"99999999999999999999", "0", "-5", "+5", "5x"}) {
    r = run_demcal({"plot", bad, "--series", "energy", "--out", "bad.png"}, d.path.string());
    EXPECT_EQ(r.rc, 2) << bad;
    EXPECT_NE(r.err.find("must be a task id"), std::string::npos) << bad << ": " << r.err;
    EXPECT_NE(r.err.find(std::string("got \"") + bad + "\""), std::string::npos) << r.err;
    EXPECT_EQ(r.err.find("9223372036854775807\""), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(d.path / "bad.png"));
  }
  // A leading zero is decimal, as query prints ids (CLI11 alone reads 010 as octal 8).
  r = run_demcal({"plot", "00" + id, "--series", "energy", "--x", "step", "--y", "total", "--out", "z.png"},
                 d.path.string());
  EXPECT_EQ(r.rc, 0) << r.err;
  r = run_demcal({"plot", "010", "--series", "energy", "--out", "bad.png"}, d.path.string());
  EXPECT_NE(r.err.find("no task with id 10"), std::string::npos) << r.err;
  // An output folder that does not exist is the command line's fault, said before gnuplot runs.
  r = run_demcal({"plot", id, "--series", "energy", "--x", "step", "--y", "total", "--out", "no/e.png"},
                 d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--out: the folder"), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find("gnuplot"), std::string::npos) << r.err;
  // So is a folder that takes no file whatever access() tells root (/proc).
  r = run_demcal({"plot", id, "--series", "energy", "--x", "step", "--y", "total", "--out", "/proc/e.png"},
                 d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--out: cannot write into the folder /proc (for /proc/e.png)"), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find("gnuplot"), std::string::npos) << r.err;
  // A file at the task's path written for another task (a database sharing the output
  // folder) is refused, not plotted.
  {
    const std::string other = d.file("other.h5");
    demcal::jobs::write_task_hdf5(other, {"collision", "0123456789abcdef", task.id, "done", ""}, nlohmann::json::object(), {}, {});
    fs::copy_file(file, d.file("mine.h5"));
    fs::copy_file(other, file, fs::copy_options::overwrite_existing);
    r = run_demcal({"plot", id, "--series", "energy", "--x", "step", "--y", "total", "--out", "o.png"}, d.path.string());
    EXPECT_EQ(r.rc, 1);
    EXPECT_NE(r.err.find("was written for another task (key 0123456789abcdef"), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(d.file("o.png")));
    fs::copy_file(d.file("mine.h5"), file, fs::copy_options::overwrite_existing);
  }
  fs::remove(file);  // the artifact went missing after the run
  r = run_demcal({"plot", id, "--series", "energy", "--x", "step", "--y", "total", "--out", "g.png"}, d.path.string());
  EXPECT_EQ(r.rc, 1);
  EXPECT_NE(r.err.find("does not exist"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(d.file("g.png")));
}

// A failed task's chart says it failed; a database moved together with its
// demcal-out/ (cluster to laptop) still plots, from the folder beside it.
TEST(Cli, PlotSaysATaskFailedAndFollowsAMovedResultsFolder) {
  TempDir d;
  fs::create_directories(d.path / "a");
  write(d.file("a/j.json"), collision_job("guard", {0.1, 1.3}, 300, 100000));  // 1.3: energy gained, stopped
  Result r = run_demcal({"run", "j.json", "--workers", "1", "--db", "x.db"}, d.file("a"));
  ASSERT_EQ(r.rc, 1) << r.err;
  fs::rename(d.path / "a", d.path / "b");
  r = run_demcal({"plot", "2", "--db", "b/x.db", "--series", "energy", "--out", "e.svg"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.err.find("/a/demcal-out/guard/"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("reading " + fs::canonical(d.path / "b").string() + "/demcal-out/guard/"), std::string::npos) << r.err;
  EXPECT_NE(r.out.find("note: task 2 is failed (unstable"), std::string::npos) << r.out;
  EXPECT_NE(slurp(d.file("e.svg")).find("task 2: energy (task failed)"), std::string::npos);
  r = run_demcal({"plot", "1", "--db", "b/x.db", "--series", "energy", "--out", "ok.svg"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_EQ(r.out.find("note:"), std::string::npos) << r.out;
  EXPECT_EQ(slurp(d.file("ok.svg")).find("(task"), std::string::npos);
  // Results in a folder of their own under the database's (a merge's parts/), moved
  // with it: found by the tail of the stored path.
  fs::create_directories(d.path / "c");
  write(d.file("c/j.json"), collision_job("deep", {0.1}));
  ASSERT_EQ(run_demcal({"run", "j.json", "--db", "m.db", "--out", "parts/out"}, d.file("c")).rc, 0);
  fs::rename(d.path / "c", d.path / "e");
  r = run_demcal({"plot", "1", "--db", "e/m.db", "--series", "energy", "--out", "deep.svg"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.err.find("reading " + fs::canonical(d.path / "e").string() + "/parts/out/deep/"), std::string::npos) << r.err;
  // query's JSON gives the paths where the files are now, and says so.
  r = run_demcal({"query", "--db", "e/m.db", "--format", "json"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_EQ(nlohmann::json::parse(r.out)[0]["hdf5"].get<std::string>().rfind(fs::canonical(d.path / "e").string() +
                                                                              "/parts/out/deep/", 0),
            0u)
      << r.out;
  EXPECT_NE(r.err.find("note: result files of 1 task(s) are not where the database recorded them"),
            std::string::npos)
      << r.err;
  // Another task's file under that name is no find: read by its key, it is missing.
  const std::string found = nlohmann::json::parse(r.out)[0]["hdf5"].get<std::string>();
  fs::path other;
  for (const auto& e : fs::directory_iterator(d.path / "b" / "demcal-out" / "guard"))
    if (e.path().extension() == ".h5") other = e.path();
  ASSERT_FALSE(other.empty());
  fs::copy_file(found, d.file("deep.h5"));
  fs::copy_file(other, found, fs::copy_options::overwrite_existing);
  r = run_demcal({"query", "--db", "e/m.db", "--format", "json"}, d.path.string());
  EXPECT_NE(r.err.find("note: result files of 1 task(s) are missing"), std::string::npos) << r.err;
  fs::copy_file(d.file("deep.h5"), found, fs::copy_options::overwrite_existing);
  fs::remove_all(d.path / "e" / "parts");
  r = run_demcal({"query", "--db", "e/m.db", "--format", "json"}, d.path.string());
  EXPECT_NE(r.err.find("note: result files of 1 task(s) are missing"), std::string::npos) << r.err;
  r = run_demcal({"plot", "1", "--db", "e/m.db", "--series", "energy", "--out", "gone.svg"}, d.path.string());
  EXPECT_EQ(r.rc, 1);
  EXPECT_NE(r.err.find("nor under " + fs::canonical(d.path / "e").string()), std::string::npos) << r.err;
}

// 50 frictionless grains (the quickstart's grid, over theta and eta, is replaced) in a
// box four times as tall as wide: over the critical-state window the axial stress
// falls below the confining one (-0.6 +- 2.9 deg on a Zen 4), and a negative phi_cv is
// no critical state: the task says so (fit then counts it among warned results). Where
// another CPU's trajectory gives a phi_cv of 0-5 deg, the test checks only that
// nothing is said.
TEST(Cli, ANegativeCriticalStateAngleIsNoResult) {
  TempDir d;
  nlohmann::json j = nlohmann::json::parse(slurp(std::string(DEMCAL_EXAMPLES_DIR) + "/quickstart.json"));
  j["name"] = "tall";
  j["triaxial"]["particles"] = 50;
  j["grid"] = {{"aspect_ratio", {4}}};
  j["threads"] = 1;
  write(d.file("j.json"), j.dump());
  const Result run = run_demcal({"run", "j.json", "--workers", "1"}, d.path.string());
  const Result q = run_demcal({"query", "--format", "json", "--metrics", "all"}, d.path.string());
  const nlohmann::json rows = nlohmann::json::parse(q.out);
  ASSERT_EQ(rows.size(), 1u) << q.out;
  if (rows[0]["status"] == "failed") {  // the trajectory is the CPU's: one of the two outcomes
    EXPECT_EQ(run.rc, 1);
    const std::string error = rows[0].value("error", "");
    EXPECT_EQ(error.rfind("invalid in stage shear: ", 0), 0u) << error;
    EXPECT_TRUE(error.find("no shear strength: phi_cv is negative") != std::string::npos ||
                error.find("the sample lost its contact network") != std::string::npos ||
                error.find("the top and bottom walls lost the sample") != std::string::npos)
        << error;
    EXPECT_FALSE(rows[0]["metrics"].contains("phi_cv_deg")) << q.out;
  } else {
    ASSERT_EQ(run.rc, 0) << run.err;
    const double cv = rows[0]["metrics"]["phi_cv_deg"].get<double>();
    const double se = rows[0]["metrics"]["phi_cv_se_deg"].get<double>();
    EXPECT_GE(cv + 2.0 * se, 0.0) << "negative beyond its noise is no result: " << q.out;
    const bool warned = rows[0].value("warning", "").find("phi_cv is negative") != std::string::npos;
    EXPECT_EQ(warned, cv < 0.0) << q.out;  // within the noise of zero: a result, warned
    EXPECT_LT(cv, 5.0) << "not the degenerate sample this test is about";
  }
}

TEST(Cli, AnOutputFolderThatCannotBeWrittenWritesNoDatabase) {
  TempDir d;
  write(d.file("j.json"), collision_job("small", {0.1}));
  write(d.file("afile"), "x");
  const Result r = run_demcal({"run", "j.json", "--db", "x.db", "--out", "afile/out"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--out: "), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find("j.json: --out"), std::string::npos) << "a flag's fault, not the job file's: " << r.err;
  EXPECT_FALSE(fs::exists(d.file("x.db")));
  EXPECT_EQ(run_demcal({"run", "j.json", "--db", ""}, d.path.string()).rc, 2);
  // Without --out the folder is the default beside the database: the error says so,
  // and does not blame --db, which is fine.
  fs::create_directories(d.path / "sub");
  write(d.file("sub/demcal-out"), "x");
  const Result def = run_demcal({"run", "j.json", "--db", "sub/x.db"}, d.path.string());
  EXPECT_EQ(def.rc, 2);
  EXPECT_EQ(def.err.rfind("demcal: error: --out (not given: the default, demcal-out/ next to --db): ", 0), 0u) << def.err;
  EXPECT_FALSE(fs::exists(d.file("sub/x.db")));
}

TEST(Cli, AnEditedJobSaysWhichTasksLeftIt) {
  TempDir d;
  write(d.file("a.json"), collision_job("small", {0.05, 0.1}));
  write(d.file("b.json"), collision_job("small", {0.05, 0.2}));
  ASSERT_EQ(run_demcal({"run", "a.json"}, d.path.string()).rc, 0);
  const Result r = run_demcal({"run", "b.json"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.err.find("its spec differs from the last run's in this database; 1 task(s) of the last run are no "
                       "longer part of it"),
            std::string::npos)
      << r.err;
  // Grown: no task leaves the job, and the run still says the spec is another one.
  write(d.file("c.json"), collision_job("small", {0.05, 0.2, 0.3}));
  const Result grown = run_demcal({"run", "c.json"}, d.path.string());
  ASSERT_EQ(grown.rc, 0) << grown.err;
  EXPECT_NE(grown.err.find("its spec differs from the last run's in this database; 1 task(s) are new, and every "
                           "task of the last run is still part of it"),
            std::string::npos)
      << grown.err;
  const Result same = run_demcal({"run", "c.json"}, d.path.string());
  EXPECT_EQ(same.err.find("spec differs"), std::string::npos) << same.err;
  // The same tasks in other words (a description added): nothing to say.
  auto spec = nlohmann::json::parse(collision_job("small", {0.05, 0.2, 0.3}));
  spec["description"] = "the same three tasks";
  write(d.file("e.json"), spec.dump());
  const Result reworded = run_demcal({"run", "e.json"}, d.path.string());
  ASSERT_EQ(reworded.rc, 0) << reworded.err;
  EXPECT_EQ(reworded.err.find("spec differs"), std::string::npos) << reworded.err;
  // The task "small" dropped (dt_factor 0.1, task 2) joins another job: the unfiltered
  // listing names that job, not its creator that no longer holds it.
  write(d.file("o.json"), collision_job("other", {0.1}));
  ASSERT_EQ(run_demcal({"run", "o.json"}, d.path.string()).rc, 0);
  const Result all = run_demcal({"query", "--format", "csv", "--metrics", "dt"}, d.path.string());
  EXPECT_NE(all.out.find("\n2,other,done,"), std::string::npos) << all.out;
  EXPECT_NE(all.out.find("\n1,small,done,"), std::string::npos) << all.out;
  // Shrunk to its first task: 0.2 and 0.3 (tasks 3, 4) are held by no job. Listed
  // under their creator, with a note, and no index in JSON.
  write(d.file("f.json"), collision_job("small", {0.05}));
  ASSERT_EQ(run_demcal({"run", "f.json"}, d.path.string()).rc, 0);
  const Result table = run_demcal({"query"}, d.path.string());
  EXPECT_NE(table.out.find("[1] tasks 3, 4: no job holds this task any more"), std::string::npos) << table.out;
  const nlohmann::json rows = nlohmann::json::parse(run_demcal({"query", "--format", "json"}, d.path.string()).out);
  ASSERT_EQ(rows.size(), 4u) << rows.dump();
  EXPECT_EQ(rows[0]["index"], 0) << rows.dump();
  EXPECT_TRUE(rows[2]["index"].is_null()) << rows.dump();
  EXPECT_EQ(rows[2]["job"], "small") << rows.dump();
}

// A task that no job holds and that finished with a warning: the warning does not
// hide the note, in the table or in CSV (a `note` column, there only when needed).
TEST(Cli, ATaskNoJobHoldsSaysSoBesideItsWarning) {
  TempDir d;
  auto job = nlohmann::json::parse(collision_job("w", {0.05, 1.3}, 300, 20000));
  job["collision"]["energy_guard"] = -1.0;  // 1.3 then finishes, warning of the energy it made
  write(d.file("a.json"), job.dump());
  ASSERT_EQ(run_demcal({"run", "a.json"}, d.path.string()).rc, 0);
  const Result held = run_demcal({"query", "--format", "csv"}, d.path.string());
  EXPECT_EQ(held.out.substr(0, held.out.find('\n')).find(",note"), std::string::npos) << held.out;
  job["grid"]["dt_factor"] = {0.05};
  write(d.file("a.json"), job.dump());
  ASSERT_EQ(run_demcal({"run", "a.json"}, d.path.string()).rc, 0);
  const Result table = run_demcal({"query"}, d.path.string());
  EXPECT_NE(table.out.find("[1] warning, [2] note"), std::string::npos) << table.out;
  EXPECT_NE(table.out.find("[2] task 2: no job holds this task any more"), std::string::npos) << table.out;
  const Result csv = run_demcal({"query", "--format", "csv"}, d.path.string());
  const std::string header = csv.out.substr(0, csv.out.find('\n'));
  EXPECT_NE(header.find(",error,warning,note"), std::string::npos) << header;
  EXPECT_NE(csv.out.find("the integration created it"), std::string::npos) << csv.out;
  EXPECT_NE(csv.out.find(",\"no job holds this task any more"), std::string::npos) << csv.out;
  // The scene's defaults a job leaves out are columns too, as in JSON's params.
  EXPECT_NE(header.find(",size_distribution,"), std::string::npos) << header;
}

// The same job file after an upgrade that changed a scene's physics (every key moves):
// the run says the build did it, not that the user edited the spec.
TEST(Cli, ARerunAfterAPhysicsChangeSaysSoNotThatTheSpecChanged) {
  TempDir d;
  write(d.file("a.json"), collision_job("small", {0.05, 0.1}));
  ASSERT_EQ(run_demcal({"run", "a.json"}, d.path.string()).rc, 0);
  demcal::test::sql(d.file("demcal.db"), "UPDATE tasks SET key = 'old-' || key");  // as an older build keyed them
  const Result r = run_demcal({"run", "a.json"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.err.find("the same spec as the last run's, but this build's physics for scene \"collision\" is version 2"),
            std::string::npos)
      << r.err;
  EXPECT_NE(r.err.find("2 task(s) of the last run are no longer part of it"), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find("spec differs"), std::string::npos) << r.err;
}
