// The runner under stress: crashing workers, a killed runner, concurrent runners
// and overlapping jobs.
#include "cli_util.hpp"

#include <sqlite3.h>

#include <algorithm>
#include <chrono>
#include <csignal>
#include <set>
#include <thread>

using namespace demcal::test;

TEST(Runner, CrashingWorkerFailsOnlyItsTask) {
  TempDir d;
  write(d.file("j.json"), collision_job("crash", {0.05, 0.1, 0.2}));
  const Result r = run_demcal({"run", "j.json", "--workers", "2"}, d.path.string(), {{"DEMCAL_TEST_ABORT_TASK", "1"}});
  EXPECT_EQ(r.rc, 1);
  const auto rows = tasks_of(d.file("demcal.db"), "crash");
  ASSERT_EQ(rows.size(), 3u);
  EXPECT_EQ(rows[0].status, "done");
  EXPECT_EQ(rows[2].status, "done");
  EXPECT_EQ(rows[1].status, "failed");
  EXPECT_NE(rows[1].error.find("SIGABRT"), std::string::npos) << rows[1].error;
  EXPECT_EQ(rows[1].attempts, 1);
  // status says why, not only how many.
  const Result st = run_demcal({"status"}, d.path.string());
  EXPECT_EQ(st.rc, 0) << st.err;
  EXPECT_NE(st.out.find("crash: task " + std::to_string(rows[1].id) + " failed: "), std::string::npos) << st.out;
  EXPECT_NE(st.out.find("SIGABRT"), std::string::npos) << st.out;
  // query: the table tags the message in its row and prints it once below; CSV keeps
  // errors and warnings in columns of their own.
  const Result q = run_demcal({"query", "--job", "crash"}, d.path.string());
  EXPECT_EQ(q.rc, 0) << q.err;
  EXPECT_NE(q.out.find("[1] error"), std::string::npos) << q.out;
  EXPECT_NE(q.out.find("[1] task " + std::to_string(rows[1].id) + ": "), std::string::npos) << q.out;
  EXPECT_EQ(q.out.find("SIGABRT"), q.out.rfind("SIGABRT")) << "the message once, under the table: " << q.out;
  const Result csv = run_demcal({"query", "--job", "crash", "--format", "csv"}, d.path.string());
  EXPECT_NE(csv.out.find(",error,warning\n"), std::string::npos) << csv.out;
  // Failed tasks stay failed on a plain re-run, and run again on request.
  EXPECT_EQ(run_demcal({"run", "j.json"}, d.path.string()).rc, 1);
  EXPECT_EQ(tasks_of(d.file("demcal.db"), "crash")[1].attempts, 1);
  EXPECT_EQ(run_demcal({"run", "j.json", "--retry-failed"}, d.path.string()).rc, 0);
  const auto again = tasks_of(d.file("demcal.db"), "crash")[1];
  EXPECT_EQ(again.status, "done");
  EXPECT_EQ(again.attempts, 2);
}

TEST(Runner, SigkillOfRunnerLosesNothingAndResumes) {
  TempDir d;
  const std::vector<double> factors = {0.05, 0.06, 0.07, 0.08, 0.09, 0.1, 0.11, 0.12};
  write(d.file("j.json"), collision_job("kill", factors, 150, 6000));
  const std::string db = d.file("demcal.db");
  const pid_t runner = spawn({"run", "j.json", "--workers", "1"}, d.path.string());
  std::vector<demcal::db::TaskRow> rows;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while (std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    if (!fs::exists(db)) continue;
    try {
      rows = tasks_of(db, "kill");
    } catch (const std::exception&) {
      continue;  // the schema may not be there yet
    }
    if (count_status(rows, "done") >= 1 && count_status(rows, "running") == 1) break;
  }
  ASSERT_GE(count_status(rows, "done"), 1);
  ASSERT_LT(count_status(rows, "done"), 8) << "the grid finished before the kill; make the tasks longer";
  kill(runner, SIGKILL);
  finish(runner, d.path.string());
  // The state the kill left behind, read after the runner is gone (nothing is claimed
  // after this): the poll above may be a task old if the runner moved on meanwhile.
  const auto killed = tasks_of(db, "kill");
  int left_running = 0;
  for (const auto& t : killed)
    if (t.status == "running") {
      ++left_running;
      // Its worker dies with the runner (PR_SET_PDEATHSIG). Wait for that rather than
      // signal the pid: reaped, the number may already name another process.
      for (int k = 0; k < 250 && t.pid > 0 && kill(static_cast<pid_t>(t.pid), 0) == 0; ++k)
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
  EXPECT_LE(left_running, 1) << "one worker, at most one task running";
  // status says no one is at work on a task the dead runner left 'running'.
  const Result st = run_demcal({"status"}, d.path.string());
  EXPECT_EQ(st.rc, 0) << st.err;
  EXPECT_EQ(st.out.find("held by a runner that is gone") != std::string::npos, left_running == 1) << st.out;
  EXPECT_EQ(st.out.find("running now"), std::string::npos) << "no one runs the orphan: " << st.out;
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  std::map<std::int64_t, demcal::db::TaskRow> done_before;
  for (const auto& t : killed)
    if (t.status == "done") done_before[t.id] = t;
  ASSERT_FALSE(done_before.empty());

  const Result r = run_demcal({"run", "j.json", "--workers", "1"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  if (left_running == 1) EXPECT_NE(r.err.find("re-queued 1 task"), std::string::npos) << r.err;
  else EXPECT_EQ(r.err.find("re-queued"), std::string::npos) << r.err;
  const auto after = tasks_of(db, "kill");
  ASSERT_EQ(after.size(), factors.size());
  EXPECT_EQ(tasks_of(db).size(), factors.size());  // no duplicates
  std::set<std::string> keys;
  for (const auto& t : after) {
    keys.insert(t.key);
    EXPECT_EQ(t.status, "done");
    if (done_before.count(t.id)) {
      EXPECT_EQ(t.started_at, done_before[t.id].started_at) << "finished task was re-run";
      EXPECT_EQ(t.attempts, 1);
    }
  }
  EXPECT_EQ(keys.size(), factors.size());
}

TEST(Runner, SigtermStopsRunningTasksForRetry) {
  TempDir d;
  write(d.file("j.json"), collision_job("term", {0.05, 0.06, 0.07, 0.08}, 150, 60000));  // long enough that the task seen running is still running at SIGTERM under load
  const std::string db = d.file("demcal.db");
  const pid_t runner = spawn({"run", "j.json", "--workers", "1"}, d.path.string());
  ASSERT_TRUE(task_seen_running(db, "term")) << "no task was seen running within 60 s";
  kill(runner, SIGTERM);
  const Result r = finish(runner, d.path.string());
  EXPECT_EQ(r.rc, 1) << r.err;
  const auto rows = tasks_of(db, "term");
  EXPECT_EQ(count_status(rows, "running"), 0);
  EXPECT_EQ(count_status(rows, "failed"), 0);
  EXPECT_GE(count_status(rows, "pending"), 1);
  // Why a task is pending again is a note in query's table, not an error.
  const Result q = run_demcal({"query", "--job", "term"}, d.path.string());
  EXPECT_NE(q.out.find("[1] note"), std::string::npos) << q.out;
  EXPECT_EQ(q.out.find("] error"), std::string::npos) << q.out;
  EXPECT_NE(q.out.find("interrupted; will be retried"), std::string::npos) << q.out;
  EXPECT_EQ(run_demcal({"run", "j.json"}, d.path.string()).rc, 0);
  EXPECT_EQ(count_status(tasks_of(db, "term"), "done"), 4);
}

// A closed terminal or SSH session (SIGHUP) stops a run as Ctrl-C does: tasks back in
// the queue, said so. Under nohup (SIGHUP ignored) the run goes on to the end.
TEST(Runner, SighupStopsRunningTasksForRetryUnlessIgnored) {
  TempDir d;
  write(d.file("j.json"), collision_job("hup", {0.05, 0.06, 0.07, 0.08}, 150, 60000));
  const std::string db = d.file("demcal.db");
  pid_t runner = spawn({"run", "j.json", "--workers", "1"}, d.path.string());
  ASSERT_TRUE(task_seen_running(db, "hup")) << "no task was seen running within 60 s";
  kill(runner, SIGHUP);
  Result r = finish(runner, d.path.string());
  EXPECT_EQ(r.rc, 1) << r.err;
  EXPECT_NE(r.err.find("hung up (SIGHUP: the terminal or session closed): stopping 1 running task(s)"), std::string::npos)
      << r.err;
  auto rows = tasks_of(db, "hup");
  EXPECT_EQ(count_status(rows, "running"), 0);
  EXPECT_GE(count_status(rows, "pending"), 1);
  // `trap '' HUP` is what nohup does: the run ignores the hangup and finishes.
  runner = spawn_program({"bash", "-c", "trap '' HUP; exec \"$0\" run j.json --workers 1", DEMCAL_BIN}, d.path.string());
  ASSERT_TRUE(task_seen_running(db, "hup")) << "no task was seen running within 60 s";
  kill(runner, SIGHUP);
  r = finish(runner, d.path.string());
  EXPECT_EQ(r.rc, 0) << r.err;
  EXPECT_EQ(count_status(tasks_of(db, "hup"), "done"), 4);
}

// A database that stops taking writes (here a file-size limit, as a full disk does)
// stops the run with what became of its tasks, and a run after it finishes the job.
TEST(Runner, ADatabaseThatCannotBeWrittenStopsTheRunAndTheNextRunFinishes) {
  TempDir d;
  write(d.file("j.json"), collision_job("full", {0.05, 0.06, 0.07, 0.08, 0.09, 0.1, 0.11, 0.12}));
  // 200 KiB: the database's log outgrows it after a few tasks; the HDF5 files do not.
  const pid_t limited = spawn_program(
      {"bash", "-c", "trap '' XFSZ; ulimit -f 200; exec \"$0\" run j.json --workers 1", DEMCAL_BIN}, d.path.string());
  const Result r = finish(limited, d.path.string());
  EXPECT_EQ(r.rc, 1) << r.err;
  EXPECT_EQ(r.err.rfind("demcal: error: "), r.err.find("demcal: error: ")) << "one error line: " << r.err;
  EXPECT_NE(r.err.find("(the run stopped: "), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("run the job again: finished tasks are kept)"), std::string::npos) << r.err;
  const Result again = run_demcal({"run", "j.json", "--workers", "1"}, d.path.string());
  EXPECT_EQ(again.rc, 0) << again.err;
  const auto rows = tasks_of(d.file("demcal.db"), "full");
  EXPECT_EQ(count_status(rows, "done"), 8);
}

TEST(Runner, AReaderThatGoesAwayDoesNotStopTheRun) {
  // `demcal run JOB | head`: the reader closes the pipe after a few lines. SIGPIPE
  // killed the runner and left its task 'running' under a dead runner.
  TempDir d;
  write(d.file("j.json"), collision_job("pipe", {0.05, 0.06, 0.07, 0.08}, 60, 3000));
  int fds[2];
  ASSERT_EQ(pipe(fds), 0);
  const pid_t pid = fork();
  if (pid == 0) {
    close(fds[0]);
    dup2(fds[1], 1);
    dup2(fds[1], 2);
    if (chdir(d.path.c_str()) != 0) _exit(126);
    execl(DEMCAL_BIN, DEMCAL_BIN, "run", "j.json", "--workers", "1", static_cast<char*>(nullptr));
    _exit(127);
  }
  close(fds[1]);
  char buf[64];
  ASSERT_GT(read(fds[0], buf, sizeof buf), 0);  // the first words, then no reader
  close(fds[0]);
  int st = 0;
  waitpid(pid, &st, 0);
  EXPECT_TRUE(WIFEXITED(st)) << "killed by signal " << (WIFSIGNALED(st) ? WTERMSIG(st) : 0);
  EXPECT_EQ(count_status(tasks_of(d.file("demcal.db"), "pipe"), "done"), 4);
}

TEST(Runner, TwoRunnersOfOneJobShareItsTasksAndRunEachOnce) {
  // Two runners of the same job at once contend for every claim: each task must be
  // run exactly once between them, and both must end cleanly.
  TempDir d;
  write(d.file("j.json"), collision_job("same", {0.05, 0.06, 0.07, 0.08, 0.09, 0.1}, 60, 2000));
  const pid_t pa = spawn({"run", "j.json", "--workers", "1"}, d.path.string(), {}, "a");
  const pid_t pb = spawn({"run", "j.json", "--workers", "1"}, d.path.string(), {}, "b");
  const Result ra = finish(pa, d.path.string(), "a"), rb = finish(pb, d.path.string(), "b");
  EXPECT_EQ(ra.rc, 0) << ra.err;
  EXPECT_EQ(rb.rc, 0) << rb.err;
  const auto rows = tasks_of(d.file("demcal.db"), "same");
  ASSERT_EQ(rows.size(), 6u);
  for (const auto& t : rows) {
    EXPECT_EQ(t.status, "done") << "task " << t.id;
    EXPECT_EQ(t.attempts, 1) << "task " << t.id << " was claimed twice";
  }
  EXPECT_EQ(tasks_of(d.file("demcal.db")).size(), 6u) << "no duplicate tasks";
}

TEST(Runner, AnOutputFolderThatCannotBeWrittenStopsTheRun) {
  // A full disk or a folder gone: the running task cannot write its files, and every
  // task after it would run to the end and fail the same way. The run stops taking
  // tasks, says why and how to go on, and leaves that task and the rest pending.
  TempDir d;
  write(d.file("j.json"), collision_job("gone", {0.05, 0.06, 0.07, 0.08, 0.09}, 150, 30000));
  const std::string db = d.file("demcal.db");
  const pid_t runner = spawn({"run", "j.json", "--workers", "1"}, d.path.string());
  ASSERT_TRUE(task_seen_running(db, "gone")) << "no task was seen running within 60 s";
  const fs::path out = fs::path(d.file("demcal-out")) / "gone";
  fs::rename(out, d.file("moved-away"));
  write(out.string(), "a file where the folder was\n");
  const Result r = finish(runner, d.path.string());
  EXPECT_EQ(r.rc, 1) << r.err;
  EXPECT_NE(r.err.find("demcal: error: stopped: task "), std::string::npos) << r.err;
  const auto rows = tasks_of(db, "gone");
  EXPECT_EQ(count_status(rows, "running"), 0);
  EXPECT_EQ(count_status(rows, "failed"), 0) << "not the tasks' failure";
  EXPECT_GE(count_status(rows, "pending"), 2) << "the task that could not write, and those after it";
  // The folder fixed, a plain rerun finishes the job.
  fs::remove(out);
  const Result again = run_demcal({"run", "j.json", "--workers", "1"}, d.path.string());
  EXPECT_EQ(again.rc, 0) << again.err;
  EXPECT_EQ(count_status(tasks_of(db, "gone"), "done"), 5);
}

TEST(Runner, ADatabaseDeletedMidRunStopsTheRunLoudly) {
  // SQLite writes on into an unlinked file: without a check the run ended "done"
  // with every result gone with the file.
  TempDir d;
  write(d.file("j.json"), collision_job("lost", {0.05, 0.06, 0.07, 0.08, 0.09, 0.1}, 150, 60000));
  const std::string db = d.file("demcal.db");
  const pid_t runner = spawn({"run", "j.json", "--workers", "1"}, d.path.string());
  ASSERT_TRUE(task_seen_running(db, "lost")) << "no task was seen running within 60 s";
  for (const char* suffix : {"", "-wal", "-shm"}) fs::remove(db + suffix);
  const Result r = finish(runner, d.path.string());
  EXPECT_EQ(r.rc, 1) << r.err;
  EXPECT_NE(r.err.find("demcal: error: the database demcal.db was deleted while this run was writing it"),
            std::string::npos) << r.err;
}

namespace {

// A backup database (job "other", 2 tasks done) and a slow run of job "slow" into
// demcal.db, seen with a task running: the scene of a database replaced mid-run.
pid_t slow_run_beside_a_backup(const TempDir& d) {
  write(d.file("other.json"), collision_job("other", {0.05, 0.06}));
  EXPECT_EQ(run_demcal({"run", "other.json", "--db", "backup.db", "--workers", "1"}, d.path.string()).rc, 0);
  write(d.file("j.json"), collision_job("slow", {0.05, 0.06, 0.07, 0.08, 0.09, 0.1}, 150, 60000));
  const pid_t runner = spawn({"run", "j.json", "--workers", "1"}, d.path.string());
  EXPECT_TRUE(task_seen_running(d.file("demcal.db"), "slow")) << "no task was seen running within 60 s";
  return runner;
}

// The backup copied over demcal.db, as a user restores one.
void restore_backup(const TempDir& d) {
  fs::copy_file(d.file("backup.db"), d.file("restore.tmp"));
  fs::rename(d.file("restore.tmp"), d.file("demcal.db"));
}

}  // namespace

// A backup copied over the database mid-run: the run stops, and its write-ahead log,
// which SQLite leaves at the path because the file it belongs to moved, must not be
// replayed into the backup by the next command (a read-only status did, and the
// backup read back as the lost file). The lost file, with the run's results, is
// saved beside it, and a merge brings them back.
TEST(Runner, ADatabaseReplacedMidRunIsNotOverwrittenByTheRunsLog) {
  TempDir d;
  const std::string db = d.file("demcal.db");
  const pid_t runner = slow_run_beside_a_backup(d);
  restore_backup(d);
  const Result r = finish(runner, d.path.string());
  EXPECT_EQ(r.rc, 1) << r.err;
  EXPECT_NE(r.err.find("was replaced by another file while this run was writing it: the run stopped, and the old "
                       "file with this run's results is saved as demcal.db.saved-"),
            std::string::npos) << r.err;
  const Result st = run_demcal({"status"}, d.path.string());
  EXPECT_EQ(st.rc, 0) << st.err;
  EXPECT_NE(st.out.find("other"), std::string::npos) << st.out;
  EXPECT_EQ(st.out.find("slow"), std::string::npos) << "the run's log was replayed into the backup:\n" << st.out;
  EXPECT_EQ(tasks_of(db, "other").size(), 2u);
  std::string saved;
  for (const auto& e : fs::directory_iterator(d.path))
    if (e.path().filename().string().rfind("demcal.db.saved-", 0) == 0) saved = e.path().filename().string();
  ASSERT_FALSE(saved.empty()) << r.err;
  EXPECT_EQ(tasks_of(d.file(saved), "slow").size(), 6u);
  const Result m = run_demcal({"merge", "--into", "demcal.db", saved}, d.path.string());
  EXPECT_EQ(m.rc, 0) << m.err;
  EXPECT_EQ(tasks_of(db, "slow").size(), 6u);
  EXPECT_EQ(tasks_of(db, "other").size(), 2u);
}

// The same with a reader of the lost file holding its log open: the truncating
// checkpoint cannot run (SQLite's pragma answered OK all the same, and the log stayed
// to be replayed into the backup), so the log and its index are moved from the path.
TEST(Runner, ADatabaseReplacedUnderAReaderIsNotOverwrittenByTheRunsLog) {
  TempDir d;
  const std::string db = d.file("demcal.db");
  const pid_t runner = slow_run_beside_a_backup(d);
  sqlite3* reader = nullptr;
  ASSERT_EQ(sqlite3_open_v2(db.c_str(), &reader, SQLITE_OPEN_READONLY, nullptr), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(reader, "BEGIN; SELECT count(*) FROM tasks;", nullptr, nullptr, nullptr), SQLITE_OK);
  restore_backup(d);
  const Result r = finish(runner, d.path.string());
  sqlite3_exec(reader, "COMMIT", nullptr, nullptr, nullptr);
  sqlite3_close(reader);
  EXPECT_EQ(r.rc, 1) << r.err;
  EXPECT_NE(r.err.find("was replaced by another file while this run was writing it"), std::string::npos) << r.err;
  const Result st = run_demcal({"status"}, d.path.string());
  EXPECT_EQ(st.rc, 0) << st.err;
  EXPECT_EQ(st.out.find("slow"), std::string::npos) << "the run's log was replayed into the backup:\n" << st.out;
  EXPECT_EQ(tasks_of(db, "other").size(), 2u);
}

TEST(Runner, TwoDatabasesSharingAnOutputFolderKeepTheirOwnResults) {
  // Two databases in one folder share the default demcal-out/, and both number their
  // tasks from 1. With result files named by task id alone, runs of one job name into
  // both at once read each other's results: one stored the other's metrics under its
  // own tasks, or failed tasks that had run. Each database must hold what a run of
  // its job alone gives, key for key.
  TempDir d;
  const std::vector<double> fa = {0.05, 0.1, 0.15, 0.2}, fb = {0.3, 0.35, 0.4, 0.45};
  write(d.file("a.json"), collision_job("same", fa, 40, 1500));
  write(d.file("b.json"), collision_job("same", fb, 40, 1500));
  ASSERT_EQ(run_demcal({"run", "a.json", "--db", "ref-a.db", "--out", "ref"}, d.path.string()).rc, 0);
  ASSERT_EQ(run_demcal({"run", "b.json", "--db", "ref-b.db", "--out", "ref"}, d.path.string()).rc, 0);
  auto metrics_by_key = [&](const std::string& db) {
    std::map<std::string, std::string> m;
    const Result q = run_demcal({"query", "--db", db, "--job", "same", "--metrics", "dt,energy_final",
                                 "--format", "csv"}, d.path.string());
    EXPECT_EQ(q.rc, 0) << q.err;
    for (const auto& t : tasks_of(d.file(db), "same")) m[t.key] = t.status;
    m["csv"] = q.out.substr(q.out.find('\n') + 1);  // the rows, without the header
    return m;
  };
  const auto ref_a = metrics_by_key("ref-a.db"), ref_b = metrics_by_key("ref-b.db");
  for (int round = 0; round < 4; ++round) {
    fs::remove_all(d.path / "demcal-out");
    for (const char* f : {"a.db", "b.db"}) fs::remove(d.file(f));
    const pid_t pa = spawn({"run", "a.json", "--db", "a.db", "--workers", "1"}, d.path.string(), {}, "a");
    const pid_t pb = spawn({"run", "b.json", "--db", "b.db", "--workers", "1"}, d.path.string(), {}, "b");
    const Result ra = finish(pa, d.path.string(), "a"), rb = finish(pb, d.path.string(), "b");
    ASSERT_EQ(ra.rc, 0) << ra.err;
    ASSERT_EQ(rb.rc, 0) << rb.err;
    EXPECT_EQ(metrics_by_key("a.db"), ref_a) << "round " << round;
    EXPECT_EQ(metrics_by_key("b.db"), ref_b) << "round " << round;
  }
}

TEST(Runner, TwoJobsConcurrentlyOnOneDatabase) {
  TempDir d;
  write(d.file("a.json"), collision_job("a", {0.05, 0.1, 0.15}, 60, 2000));
  write(d.file("b.json"), collision_job("b", {0.06, 0.12, 0.18}, 60, 2000));
  const pid_t pa = spawn({"run", "a.json", "--workers", "1"}, d.path.string(), {}, "a");
  const pid_t pb = spawn({"run", "b.json", "--workers", "1"}, d.path.string(), {}, "b");
  const Result ra = finish(pa, d.path.string(), "a"), rb = finish(pb, d.path.string(), "b");
  EXPECT_EQ(ra.rc, 0) << ra.err;
  EXPECT_EQ(rb.rc, 0) << rb.err;
  const auto all = tasks_of(d.file("demcal.db"));
  EXPECT_EQ(all.size(), 6u);
  EXPECT_EQ(count_status(all, "done"), 6);
  for (const auto& t : all) EXPECT_EQ(t.attempts, 1);
}

TEST(Runner, AnotherJobFileRecordedUnderTheSameNameStopsTheFirstRunLoudly) {
  // Run a works through its own tasks; meanwhile run b records another job file
  // under the same name. a must not take up b's tasks nor print them as its own.
  TempDir d;
  write(d.file("a.json"), collision_job("same", {0.05, 0.06, 0.07, 0.08}, 300, 60000));
  write(d.file("b.json"), collision_job("same", {0.2, 0.3}, 30, 400));
  const pid_t pa = spawn({"run", "a.json", "--workers", "1"}, d.path.string(), {}, "a");
  for (int i = 0; i < 600; ++i) {  // until a has claimed its first task
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    if (!fs::exists(d.file("demcal.db"))) continue;
    try {
      const auto rows = tasks_of(d.file("demcal.db"), "same");
      if (std::any_of(rows.begin(), rows.end(), [](const auto& t) { return t.status == "running"; })) break;
    } catch (const std::exception&) {
      // a has made the file but not yet its tables
    }
  }
  const Result rb = finish(spawn({"run", "b.json", "--workers", "1"}, d.path.string(), {}, "b"), d.path.string(), "b");
  EXPECT_EQ(rb.rc, 0) << rb.err;
  const Result ra = finish(pa, d.path.string(), "a");
  EXPECT_EQ(ra.rc, 1) << ra.err;
  EXPECT_NE(ra.err.find("job same was recorded again from a different job file by another run"), std::string::npos)
      << ra.err;
  EXPECT_EQ(ra.out.find("0.2"), std::string::npos) << "b's tasks printed as a's: " << ra.out;
  // b's tasks were run by b alone, once each.
  for (const auto& t : tasks_of(d.file("demcal.db"), "same")) {
    EXPECT_EQ(t.status, "done");
    EXPECT_EQ(t.attempts, 1);
  }
  // a stopped taking its own queued tasks once they had left the job: of its four
  // (each ~0.3 s; b recorded while the first ran) some were never started.
  int pending = 0;
  for (const auto& t : tasks_of(d.file("demcal.db"))) pending += t.status == "pending";
  EXPECT_GE(pending, 1) << ra.err;
}

TEST(Runner, OverlappingJobsReuseFinishedWorkByKey) {
  TempDir d;
  write(d.file("a.json"), collision_job("a", {0.1, 0.2}));
  write(d.file("b.json"), collision_job("b", {0.2, 0.3}));
  ASSERT_EQ(run_demcal({"run", "a.json"}, d.path.string()).rc, 0);
  const Result r = run_demcal({"run", "b.json"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.err.find("1 of 2 task(s) already done"), std::string::npos) << r.err;
  const auto a = tasks_of(d.file("demcal.db"), "a"), b = tasks_of(d.file("demcal.db"), "b");
  EXPECT_EQ(a[1].id, b[0].id);
  EXPECT_EQ(b[0].attempts, 1);
  EXPECT_EQ(tasks_of(d.file("demcal.db")).size(), 3u);
  const Result q = run_demcal({"query", "--job", "b", "--format", "csv"}, d.path.string());
  EXPECT_EQ(std::count(q.out.begin(), q.out.end(), '\n'), 3);
}
