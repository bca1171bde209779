// The MPI task farm under a real mpirun (built and registered only with DEMCAL_MPI=ON).
#include "dist_util.hpp"
#include "jobs/runner.hpp"

using namespace demcal::test;

namespace {

const std::vector<double> kFactors = {0.05, 0.07, 0.09, 0.11, 0.13, 0.15};

const std::map<std::string, std::string> kMpiEnv = {
    {"OMPI_ALLOW_RUN_AS_ROOT", "1"},  // the tests may run as root (CI containers)
    {"OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1"},
};

Result mpirun(int ranks, const std::vector<std::string>& mpi_flags, const std::vector<std::string>& demcal_args,
              const std::string& dir, std::map<std::string, std::string> env = {}) {
  std::vector<std::string> argv = {DEMCAL_MPIEXEC, "-np", std::to_string(ranks), "--oversubscribe"};
  argv.insert(argv.end(), mpi_flags.begin(), mpi_flags.end());
  argv.push_back(DEMCAL_BIN);
  argv.insert(argv.end(), demcal_args.begin(), demcal_args.end());
  env.insert(kMpiEnv.begin(), kMpiEnv.end());
  return run_program(argv, dir, env);
}

}  // namespace

TEST(Mpi, FarmEqualsLocalRunBitForBit) {
  TempDir d;
  write(d.file("j.json"), collision_job("farm", kFactors));  // threads = 1, as the local run
  const Result local = run_demcal({"run", "j.json", "--db", "local.db", "--workers", "2"}, d.path.string());
  ASSERT_EQ(local.rc, 0) << local.err;
  const Result r = mpirun(3, {}, {"run", "j.json", "--mpi", "--db", "mpi.db"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.err.find("MPI task farm: 2 worker rank(s), 6 task(s)"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("on rank 1"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("on rank 2"), std::string::npos) << r.err;
  EXPECT_GT(expect_same_results(d.file("local.db"), d.file("mpi.db"), "farm"), 6 * 3);
  // Only rank 0 opened a database; every task ran once and wrote its series.
  EXPECT_FALSE(fs::exists(d.file("demcal.db")));
  demcal::db::Store s(d.file("mpi.db"), true);
  for (const auto& t : s.tasks("farm")) {
    EXPECT_EQ(t.attempts, 1);
    ASSERT_EQ(s.artifacts(t.id).size(), 1u);
    EXPECT_TRUE(fs::exists(s.artifacts(t.id)[0].second));
  }
  // Resumable like a local run: everything is reused.
  const Result again = mpirun(3, {}, {"run", "j.json", "--mpi", "--db", "mpi.db"}, d.path.string());
  EXPECT_EQ(again.rc, 0) << again.err;
  EXPECT_NE(again.err.find("6 of 6 task(s) already done"), std::string::npos) << again.err;
}

TEST(Mpi, CrashingTaskFailsOnlyItsTask) {
  TempDir d;
  write(d.file("j.json"), collision_job("crash", {0.05, 0.1, 0.2}));
  const Result r = mpirun(3, {}, {"run", "j.json", "--mpi"}, d.path.string(), {{"DEMCAL_TEST_ABORT_TASK", "1"}});
  EXPECT_EQ(r.rc, 1) << r.err;
  const auto rows = tasks_of(d.file("demcal.db"), "crash");
  ASSERT_EQ(rows.size(), 3u);
  EXPECT_EQ(rows[0].status, "done");
  EXPECT_EQ(rows[1].status, "failed");
  EXPECT_NE(rows[1].error.find("SIGABRT"), std::string::npos) << rows[1].error;
  EXPECT_EQ(rows[2].status, "done");
}

// OpenMPI run with --enable-recovery keeps the job alive when a rank dies: rank 0
// notices the silence, fails the lost rank's task with the reason and finishes.
TEST(Mpi, KilledWorkerRankIsReportedAndRankZeroFinishes) {
  TempDir d;
  write(d.file("j.json"), collision_job("lost", kFactors));
  fs::create_directories(d.path / "tmp");  // the ranks' TMPDIR: the lost one leaves nothing of demcal's there
  const auto t0 = std::chrono::steady_clock::now();
  const Result r = mpirun(3, {"--enable-recovery"}, {"run", "j.json", "--mpi", "--mpi-timeout", "3"}, d.path.string(),
                          {{"DEMCAL_TEST_KILL_RANK_TASK", "1"}, {"TMPDIR", d.file("tmp")}});
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  // (mpirun --enable-recovery exits 0 whatever rank 0 returns; the log and the database tell.)
  EXPECT_NE(r.err.find("lost: no message for 3 s"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("5 done (0 reused), 1 failed"), std::string::npos) << r.err;
  EXPECT_LT(wall, 45);
  const auto rows = tasks_of(d.file("demcal.db"), "lost");
  ASSERT_EQ(rows.size(), kFactors.size());
  EXPECT_EQ(count_status(rows, "done"), 5);
  EXPECT_EQ(rows[1].status, "failed");
  EXPECT_NE(rows[1].error.find("worker rank"), std::string::npos) << rows[1].error;
  EXPECT_NE(rows[1].error.find("lost"), std::string::npos) << rows[1].error;
  for (const auto& e : fs::directory_iterator(d.path / "tmp"))
    EXPECT_NE(e.path().filename().string().rfind("demcal", 0), 0u) << "left behind: " << e.path();
  // The lost task runs again on request.
  const Result retry = run_demcal({"run", "j.json", "--retry-failed"}, d.path.string());
  EXPECT_EQ(retry.rc, 0) << retry.err;
  EXPECT_EQ(count_status(tasks_of(d.file("demcal.db"), "lost"), "done"), 6);
}

// Rank 0 stalled (a slow database write) longer than the timeout (2.5 s against 2 s) while workers
// keep talking: their messages are read before their silence is judged, so no
// live rank is declared lost.
TEST(Mpi, RankZeroStallIsNotAWorkersSilence) {
  TempDir d;
  write(d.file("j.json"), collision_job("stall", {0.05, 0.07, 0.09, 0.11}));
  const Result r = mpirun(3, {}, {"run", "j.json", "--mpi", "--mpi-timeout", "2"}, d.path.string(),
                          {{"DEMCAL_TEST_ROOT_STALL_S", "2.5"}});
  EXPECT_EQ(r.rc, 0) << r.err;
  EXPECT_EQ(r.err.find(" lost:"), std::string::npos) << r.err;
  EXPECT_EQ(count_status(tasks_of(d.file("demcal.db"), "stall"), "done"), 4) << r.err;
}

// Plain mpirun (no recovery) aborts the whole job when a rank dies: it must end,
// not hang, and the next run picks up what was unfinished.
TEST(Mpi, KilledWorkerRankWithoutRecoveryEndsTheJobAndTheNextRunResumes) {
  TempDir d;
  write(d.file("j.json"), collision_job("abort", kFactors));
  const Result r = mpirun(3, {}, {"run", "j.json", "--mpi", "--mpi-timeout", "2"}, d.path.string(),
                          {{"DEMCAL_TEST_KILL_RANK_TASK", "1"}});
  EXPECT_NE(r.rc, 0) << r.err;
  const auto rows = tasks_of(d.file("demcal.db"), "abort");
  EXPECT_LT(count_status(rows, "done"), 6);
  // A worker rank's result file of the dead farm (one a rank killed while writing it
  // would leave, planted so that there surely is one): the next run removes it.
  std::vector<std::string> tokens;
  {
    demcal::db::Store s(d.file("demcal.db"));
    tokens = s.runner_tokens();
  }
  ASSERT_EQ(tokens.size(), 1u) << r.err;
  const fs::path out = d.path / "demcal-out" / "abort";
  ASSERT_TRUE(fs::is_directory(out));
  const fs::path orphan = out / (".task-99." + demcal::jobs::file_name_safe(tokens[0]) + ".rank1.result.json");
  write(orphan.string(), "{}");
  const Result resume = run_demcal({"run", "j.json"}, d.path.string());
  EXPECT_EQ(resume.rc, 0) << resume.err;
  EXPECT_EQ(count_status(tasks_of(d.file("demcal.db"), "abort"), "done"), 6);
  // Once more, everything reused: a rank of the dead farm still dying as the resume
  // started (mpirun's teardown under load) has written its last file by now.
  const Result again = run_demcal({"run", "j.json"}, d.path.string());
  EXPECT_EQ(again.rc, 0) << again.err;
  EXPECT_FALSE(fs::exists(orphan)) << resume.err << again.err;
  for (const auto& e : fs::directory_iterator(out))
    EXPECT_NE(e.path().filename().string().rfind(".task-", 0), 0u)
        << "left behind: " << e.path() << "\n" << resume.err << again.err;
}

// A deleted database takes every later result with it: rank 0 must stop handing
// out tasks within seconds, not run the whole queue into an unlinked file.
TEST(Mpi, ADatabaseDeletedMidRunStopsTheHandOut) {
  TempDir d;
  const std::vector<double> factors = {0.05, 0.06, 0.07, 0.08, 0.09, 0.1, 0.11, 0.12};
  write(d.file("j.json"), collision_job("gone", factors, 150, 600000));
  std::vector<std::string> argv = {DEMCAL_MPIEXEC, "-np", "3", "--oversubscribe", DEMCAL_BIN, "run", "j.json", "--mpi"};
  const pid_t pid = spawn_program(argv, d.path.string(), kMpiEnv);
  const std::string db = d.file("demcal.db");
  ASSERT_TRUE(task_seen_running(db, "gone")) << "no task was seen running within 60 s";
  for (const char* suffix : {"", "-wal", "-shm"}) fs::remove(db + suffix);
  const Result r = finish(pid, d.path.string());
  EXPECT_NE(r.rc, 0) << r.err;
  EXPECT_NE(r.err.find("was deleted while this run was writing it"), std::string::npos) << r.err;
  int started = 0;
  for (std::size_t at = r.err.find("started on rank"); at != std::string::npos; at = r.err.find("started on rank", at + 1))
    ++started;
  EXPECT_LE(started, 4) << "tasks went on being handed out after the database was gone:\n" << r.err;
}

// The task folder replaced by a file mid-run (a disk gone or full): the running
// task cannot write its files, and every task after it would fail the same way. As
// a local run does, the farm stops handing out work, leaves those tasks pending
// (not failed: not their fault) and says so; the folder fixed, a rerun finishes.
TEST(Mpi, AnOutputFolderThatCannotBeWrittenStopsTheHandOut) {
  TempDir d;
  write(d.file("j.json"), collision_job("nowhere", {0.05, 0.06, 0.07, 0.08, 0.09, 0.1}, 150, 30000));
  const pid_t pid = spawn_program({DEMCAL_MPIEXEC, "-np", "2", "--oversubscribe", DEMCAL_BIN, "run", "j.json", "--mpi"},
                                  d.path.string(), kMpiEnv);
  const std::string db = d.file("demcal.db");
  ASSERT_TRUE(task_seen_running(db, "nowhere")) << "no task was seen running within 60 s";
  const fs::path out = d.path / "demcal-out" / "nowhere";
  fs::rename(out, d.file("moved-away"));
  write(out.string(), "a file where the folder was\n");
  const Result r = finish(pid, d.path.string());
  EXPECT_NE(r.rc, 0) << r.err;
  EXPECT_NE(r.err.find("could not write its files, back in the queue"), std::string::npos) << r.err;
  const auto rows = tasks_of(db, "nowhere");
  EXPECT_EQ(count_status(rows, "running"), 0) << r.err;
  EXPECT_EQ(count_status(rows, "failed"), 0) << "not the tasks' failure\n" << r.err;
  EXPECT_GE(count_status(rows, "pending"), 2) << "the task that could not write, and those after it\n" << r.err;
  fs::remove(out);
  const Result again = mpirun(2, {}, {"run", "j.json", "--mpi"}, d.path.string());
  EXPECT_EQ(again.rc, 0) << again.err;
  EXPECT_EQ(count_status(tasks_of(db, "nowhere"), "done"), 6) << again.err;
}

// A database rank 0 cannot write (here its file outgrows a size limit) stops the farm
// as it stops a local run: one error saying what became of the work, the tasks it
// held back in the queue, and the next run finishes them.
TEST(Mpi, ADatabaseThatCannotBeWrittenStopsTheFarmAndTheNextRunFinishes) {
  TempDir d;
  write(d.file("j.json"), collision_job("full", {0.05, 0.06, 0.07, 0.08, 0.09, 0.1, 0.11, 0.12}));
  // The limit on the ranks only: mpirun's own shared-memory store must not hit it.
  const pid_t limited = spawn_program({DEMCAL_MPIEXEC, "-np", "3", "--oversubscribe", "bash", "-c",
                                       "trap '' XFSZ; ulimit -f 200; exec \"$0\" run j.json --mpi", DEMCAL_BIN},
                                      d.path.string(), kMpiEnv);
  const Result r = finish(limited, d.path.string());
  EXPECT_NE(r.rc, 0) << r.err;
  EXPECT_NE(r.err.find("(the run stopped: "), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("run the job again: finished tasks are kept)"), std::string::npos) << r.err;
  const Result again = mpirun(3, {}, {"run", "j.json", "--mpi"}, d.path.string());
  EXPECT_EQ(again.rc, 0) << again.err;
  EXPECT_EQ(count_status(tasks_of(d.file("demcal.db"), "full"), "done"), 8);
}

TEST(Mpi, BadInputUnderMpirunEndsEveryRank) {
  TempDir d;
  write(d.file("bad.json"), R"({"name": "b", "scene": "collision", "material": {"theta_deg": 90}})");
  Result r = mpirun(3, {}, {"run", "bad.json", "--mpi"}, d.path.string());
  EXPECT_EQ(r.rc, 2) << r.err;
  EXPECT_NE(r.err.find("material.theta_deg"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(d.file("demcal.db")));
  write(d.file("j.json"), collision_job("one", {0.1}));
  r = mpirun(1, {}, {"run", "j.json", "--mpi"}, d.path.string());
  EXPECT_EQ(r.rc, 2) << r.err;  // bad input, as any other refusal of how demcal was started
  EXPECT_NE(r.err.find("at least 2 ranks"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(d.file("demcal.db")));
}
