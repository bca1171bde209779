// Who holds a running task, and when a run may take it back: a runner on this host
// by its process, one on another host by its heartbeat in the database.
#include "../temp_dir.hpp"
#include "db/store.hpp"
#include "jobs/leftover_files.hpp"
#include "jobs/liveness.hpp"
#include "jobs/runner.hpp"

#include <gtest/gtest.h>
#include <sqlite3.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <unistd.h>

namespace demcal::jobs {
namespace {

std::vector<db::NewTask> three_tasks() {
  std::vector<db::NewTask> out;
  for (const char* k : {"k1", "k2", "k3"}) out.push_back({k, "collision", std::string("{\"k\":\"") + k + "\"}"});
  return out;
}

void age_heartbeat(const std::string& path, const std::string& token, double seconds) {
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
  const std::string sql =
      "UPDATE runners SET last_seen = last_seen - " + std::to_string(seconds) + " WHERE token = '" + token + "'";
  ASSERT_EQ(sqlite3_exec(db, sql.c_str(), nullptr, nullptr, nullptr), SQLITE_OK) << sqlite3_errmsg(db);
  sqlite3_close(db);
}

TEST(Liveness, ARunnerOnAnotherHostIsJudgedByItsHeartbeat) {
  demcal::test::TempDir d;
  const std::string path = d.file("a.db");
  db::Store s(path);
  s.put_job("j", "{}", three_tasks());
  const auto rows = s.tasks("j");
  const std::string beating = "node01:30457:123", silent = "node02:411:77", legacy = "node03:9:1";
  ASSERT_TRUE(s.claim(rows[0].id, beating));
  ASSERT_TRUE(s.claim(rows[1].id, silent));
  ASSERT_TRUE(s.claim(rows[2].id, legacy));  // a runner from before heartbeats: never beat
  s.beat(beating);
  s.beat(silent);
  age_heartbeat(path, silent, kRunnerLeaseS + 5);
  age_heartbeat(path, beating, kRunnerLeaseS - 30);  // late, but within the lease
  EXPECT_TRUE(holder_alive(s, beating));
  EXPECT_FALSE(holder_alive(s, silent));
  EXPECT_TRUE(holder_alive(s, legacy));
  // A runner keeping a watch does not believe a stale beat at first sight (the host's
  // clock may run behind); without one (status, an MPI run's start) the stamp decides.
  BeatWatch w;
  EXPECT_EQ(requeue_dead_runners(s, &w), 0);
  EXPECT_NE(describe_holder(s, silent, &w).find("re-queued unless a beat arrives within 30 s"), std::string::npos)
      << describe_holder(s, silent, &w);
  EXPECT_EQ(requeue_dead_runners(s), 1);
  EXPECT_EQ(s.task(rows[1].id)->status, "pending");
  EXPECT_EQ(s.task(rows[0].id)->status, "running");
  EXPECT_EQ(s.task(rows[2].id)->status, "running");
  EXPECT_NE(describe_holder(s, beating).find("another host, last seen"), std::string::npos);
  EXPECT_NE(describe_holder(s, legacy).find("--requeue-running"), std::string::npos);
  // The user says the legacy runner is gone: the job's running tasks go back.
  std::ostringstream log;
  EXPECT_EQ(requeue_running_tasks(s, *s.find_job("j"), log), 2);
  for (const auto& r : s.tasks("j")) EXPECT_EQ(r.status, "pending");
  EXPECT_NE(log.str().find("re-queued 2 running task(s) (--requeue-running)"), std::string::npos) << log.str();
}

// A runner killed by SIGKILL leaves its workers' result files and HDF5 parts in the
// job's folder; the next run removes those of runners that are gone, and nothing of a
// live runner's, of another host's, or of a runner it has no token of.
TEST(Liveness, TheFilesOfADeadRunnerAreRemovedAndNoOneElses) {
  demcal::test::TempDir d;
  db::Store s(d.file("a.db"));
  const std::string here = runner_token(), gone_here = hostname() + ":999999999:1", elsewhere = "node03:9:1";
  for (const auto& t : {here, gone_here, elsewhere}) s.beat(t);
  const std::filesystem::path dir = d.file("out");
  std::filesystem::create_directories(dir);
  const auto touch = [&](const std::string& name) {
    std::ofstream(dir / name) << "x";
    return dir / name;
  };
  const auto dead_result = touch(".task-3." + file_name_safe(gone_here) + ".result.json");
  const auto dead_tmp = touch(".task-4." + file_name_safe(gone_here) + ".result.json.tmp");
  // An MPI farm's worker rank's file: its farm's rank 0 is the runner that is gone.
  const auto dead_rank = touch(".task-13." + file_name_safe(gone_here) + ".rank2.result.json");
  const auto live_rank = touch(".task-14." + file_name_safe(here) + ".rank1.result.json");
  const auto dead_part = touch("7-abc.h5." + process_host_tag() + "-999999999.part");
  // Another container with this hostname: its pids are not ours to judge.
  const auto other_namespace = touch("12-mno.h5." + hostname() + "-pidns1-999999999.part");
  const auto live_result = touch(".task-5." + file_name_safe(here) + ".result.json");
  const auto other_host = touch(".task-6." + file_name_safe(elsewhere) + ".result.json");
  const auto unknown = touch(".task-8." + file_name_safe("node04:1:1") + ".result.json");
  const auto live_part = touch("9-def.h5." + process_host_tag() + "-" + std::to_string(getpid()) + ".part");
  const auto other_part = touch("10-ghi.h5.node03-999999999.part");
  const auto task_file = touch("11-jkl.h5");
  EXPECT_EQ(remove_leftovers_of_dead_runners(dir, s, "not-this-one", nullptr), 4);
  for (const auto& p : {dead_result, dead_tmp, dead_part, dead_rank}) EXPECT_FALSE(std::filesystem::exists(p)) << p;
  for (const auto& p : {live_result, other_host, unknown, live_part, other_part, other_namespace, task_file, live_rank})
    EXPECT_TRUE(std::filesystem::exists(p)) << p;
  // Another host's runner silent past the lease: a watch that has just met it still
  // believes it alive (that host's clock may run behind); judged by the stamp, gone.
  age_heartbeat(d.file("a.db"), elsewhere, kRunnerLeaseS + 5);
  BeatWatch fresh;
  EXPECT_EQ(remove_leftovers_of_dead_runners(dir, s, "not-this-one", &fresh), 0);
  EXPECT_TRUE(std::filesystem::exists(other_host));
  EXPECT_EQ(remove_leftovers_of_dead_runners(dir, s, "not-this-one", nullptr), 1);
  EXPECT_FALSE(std::filesystem::exists(other_host));
  EXPECT_EQ(remove_leftovers_of_dead_runners(d.file("missing"), s, "x", nullptr), 0);  // no folder: nothing to do
}

// --requeue-running takes the user's word for runners elsewhere, but a runner alive on
// this host would go on running its tasks beside the new run: those are left, and said.
TEST(Liveness, RequeueRunningLeavesTheTasksOfARunnerAliveOnThisHost) {
  demcal::test::TempDir d;
  db::Store s(d.file("a.db"));
  s.put_job("j", "{}", three_tasks());
  const auto rows = s.tasks("j");
  const std::string here = runner_token();  // this test process: alive, on this host
  const std::string gone_here = hostname() + ":999999999:1", elsewhere = "node03:9:1";
  ASSERT_TRUE(s.claim(rows[0].id, here));
  ASSERT_TRUE(s.claim(rows[1].id, gone_here));
  ASSERT_TRUE(s.claim(rows[2].id, elsewhere));
  std::ostringstream log;
  EXPECT_EQ(requeue_running_tasks(s, *s.find_job("j"), log), 2);
  EXPECT_EQ(s.task(rows[0].id)->status, "running");
  EXPECT_EQ(s.task(rows[1].id)->status, "pending");
  EXPECT_EQ(s.task(rows[2].id)->status, "pending");
  EXPECT_NE(log.str().find("left the tasks of " + here + " running: that runner is alive on this host"), std::string::npos)
      << log.str();
  // A running task without a holder (a hand edit) is nobody's: re-queued too.
  ASSERT_TRUE(s.claim(rows[1].id, elsewhere));
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(d.file("a.db").c_str(), &db), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(db, ("UPDATE tasks SET worker = NULL WHERE id = " + std::to_string(rows[1].id)).c_str(), nullptr,
                         nullptr, nullptr),
            SQLITE_OK);
  sqlite3_close(db);
  EXPECT_EQ(requeue_running_tasks(s, *s.find_job("j"), log), 1);
  EXPECT_EQ(s.task(rows[1].id)->status, "pending");
  EXPECT_EQ(s.task(rows[0].id)->status, "running");
}

TEST(Liveness, AWatchTellsAClockBehindOursFromASilentRunner) {
  BeatWatch w;
  const double now = 1e9, lag = 600;  // node01's clock runs 10 minutes behind ours
  // Its beats look 10 minutes old, but a new one arrives every 10 s of our clock.
  for (int k = 0; k <= 12; ++k)
    EXPECT_TRUE(w.alive("node01:1:1", now + 10 * k - lag, now + 10 * k, 10.0 * k)) << "beat " << k;
  ASSERT_TRUE(w.clock_behind("node01:1:1").has_value());
  EXPECT_NEAR(*w.clock_behind("node01:1:1"), lag, 1e-9);
  // A runner that stopped beating with the same stale stamp: believed after three beats' time.
  EXPECT_TRUE(w.alive("node02:1:1", now - lag, now, 0.0));
  EXPECT_TRUE(w.alive("node02:1:1", now - lag, now + 29, 29.0));
  EXPECT_FALSE(w.alive("node02:1:1", now - lag, now + 31, 31.0));
  EXPECT_FALSE(w.clock_behind("node02:1:1").has_value());  // never seen to beat
  // A clock ahead of ours: its stamp looks fresh for ever; silent for a lease of our clock, dead.
  const double ahead = now + 3600;
  EXPECT_TRUE(w.alive("node03:1:1", ahead, now, 0.0));
  EXPECT_TRUE(w.alive("node03:1:1", ahead, now + kRunnerLeaseS - 1, kRunnerLeaseS - 1));
  EXPECT_FALSE(w.alive("node03:1:1", ahead, now + kRunnerLeaseS, kRunnerLeaseS));
  // Never beat (a demcal from before heartbeats): assumed alive, as without a watch.
  EXPECT_TRUE(w.alive("node04:1:1", std::nullopt, now, 500.0));
}

TEST(Liveness, ARunnerOnThisHostIsJudgedByItsProcess) {
  demcal::test::TempDir d;
  db::Store s(d.file("a.db"));
  EXPECT_TRUE(holder_alive(s, runner_token()));
  // This host, a pid that cannot be ours with a start time that cannot match.
  const std::string mine = runner_token();
  const std::string host = mine.substr(0, mine.find(':'));
  EXPECT_FALSE(holder_alive(s, host + ":" + std::to_string(getpid()) + ":1"));
  // A token from before the pid namespace was part of the host: judged by its process too.
  const std::string bare = host.substr(0, host.find("/pidns"));
  EXPECT_FALSE(holder_alive(s, bare + ":" + std::to_string(getpid()) + ":1"));
}

TEST(Liveness, ARunnerInAnotherPidNamespaceOfThisHostIsJudgedByItsHeartbeat) {
  // Two containers sharing a hostname: the other's pid means nothing here, so its
  // heartbeat decides, as for another host.
  demcal::test::TempDir d;
  db::Store s(d.file("a.db"));
  const std::string mine = runner_token();
  const std::string host = mine.substr(0, mine.find(':'));
  ASSERT_NE(host.find("/pidns"), std::string::npos) << mine;
  const std::string bare = host.substr(0, host.find("/pidns"));
  const std::string other = bare + "/pidns1:" + std::to_string(getpid()) + ":1";  // a pid that is not that runner here
  { Heartbeat beat(s, other); }  // beats now
  EXPECT_TRUE(holder_alive(s, other)) << "a fresh heartbeat, whatever this namespace's pid says";
  EXPECT_NE(describe_holder(s, other, nullptr).find("another host"), std::string::npos);
}

}  // namespace
}  // namespace demcal::jobs
