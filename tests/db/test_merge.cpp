// The merge rules of db/merge.hpp beyond new / identical / conflict: which result
// wins when the destination and a part disagree on a task's status.
#include "db/merge.hpp"
#include "db/store.hpp"

#include "../temp_dir.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <csignal>
#include <filesystem>
#include <sys/wait.h>
#include <unistd.h>

using demcal::test::TempDir;
using demcal::db::MergeReport;
using demcal::db::NewTask;
using demcal::db::Outcome;
using demcal::db::Store;

namespace {

// One job "j" of three tasks a, b, c; each given a state: "pending", "running",
// "done" (metric x = value) or "failed".
struct State {
  std::string status;
  double x = 0.0;
};
void write_db(const std::string& path, const std::vector<State>& states) {
  Store s(path);
  std::vector<NewTask> tasks;
  for (std::size_t i = 0; i < states.size(); ++i)
    tasks.push_back({std::string(1, static_cast<char>('a' + i)), "collision", "{\"i\":" + std::to_string(i) + "}"});
  s.put_job("j", "{\"spec\":1}", tasks);
  const auto rows = s.tasks("j");
  for (std::size_t i = 0; i < states.size(); ++i) {
    if (states[i].status == "pending") continue;
    ASSERT_TRUE(s.claim(rows[i].id, "w"));
    if (states[i].status == "running") continue;
    Outcome o;
    o.status = states[i].status;
    o.wall_s = 1.0;
    if (o.status == "done") o.metrics = {{"x", states[i].x}};
    else o.error = "broke";
    ASSERT_TRUE(s.finish(rows[i].id, "w", o));
  }
}

std::string status_of(Store& s, const std::string& key) {
  for (const auto& t : s.tasks("j"))
    if (t.key == key) return t.status;
  return "missing";
}
double x_of(Store& s, const std::string& key) {
  for (const auto& t : s.tasks("j"))
    if (t.key == key)
      for (const auto& [n, v] : s.metrics(t.id))
        if (n == "x") return v;
  return NAN;
}

}  // namespace

TEST(Merge, FinishedResultReplacesFailedOrUnfinishedAndIsKeptOverThem) {
  TempDir d;
  // Destination: a failed, b done (x = 2), c pending.
  write_db(d.file("dest.db"), {{"failed"}, {"done", 2.0}, {"pending"}});
  // Part: a done (x = 1), b failed, c running (its runner is elsewhere, perhaps gone).
  write_db(d.file("part.db"), {{"done", 1.0}, {"failed"}, {"running"}});
  const MergeReport r = demcal::db::merge_databases(d.file("dest.db"), {d.file("part.db")});
  EXPECT_EQ(r.results_taken, 1) << "a: the part's finished result replaces the destination's failure";
  EXPECT_EQ(r.kept, 1) << "b: the destination's finished result is kept over the part's failure";
  EXPECT_TRUE(r.conflicts.empty());
  Store s(d.file("dest.db"), /*read_only=*/true);
  EXPECT_EQ(status_of(s, "a"), "done");
  EXPECT_EQ(x_of(s, "a"), 1.0);
  EXPECT_EQ(status_of(s, "b"), "done");
  EXPECT_EQ(x_of(s, "b"), 2.0);
  EXPECT_EQ(status_of(s, "c"), "pending") << "a task running elsewhere is not running here";
}

TEST(Merge, RunningTaskOfAPartArrivesAsPendingAndMergingTwiceChangesNothing) {
  TempDir d;
  Store(d.file("dest.db"));  // an empty destination
  write_db(d.file("part.db"), {{"done", 3.0}, {"running"}, {"failed"}});
  const MergeReport first = demcal::db::merge_databases(d.file("dest.db"), {d.file("part.db")});
  EXPECT_EQ(first.tasks_added, 3);
  Store s(d.file("dest.db"), /*read_only=*/true);
  EXPECT_EQ(status_of(s, "a"), "done");
  EXPECT_EQ(status_of(s, "b"), "pending");
  EXPECT_EQ(status_of(s, "c"), "failed");
  const MergeReport again = demcal::db::merge_databases(d.file("dest.db"), {d.file("part.db")});
  EXPECT_EQ(again.tasks_added, 0);
  EXPECT_EQ(again.results_taken, 0);
  EXPECT_EQ(again.identical, 2) << "a: done in both, the same; c: failed in both";
  EXPECT_TRUE(again.conflicts.empty());
}

namespace {
std::vector<std::string> names_in(const std::string& dir) {
  std::vector<std::string> out;
  for (const auto& e : std::filesystem::directory_iterator(dir)) out.push_back(e.path().filename().string());
  std::sort(out.begin(), out.end());
  return out;
}
}  // namespace

TEST(Merge, AStoppedMergeLeavesNoDestinationItMadeAndAnExistingOneAsItWas) {
  TempDir d;
  write_db(d.file("part.db"), {{"done", 1.0}, {"failed"}, {"done", 3.0}});
  // Stopped after the first task row: a new destination is not left behind, half-made or empty.
  int asked = 0;
  const auto stop_at_second_row = [&] { return ++asked > 2; };
  EXPECT_THROW(demcal::db::merge_databases(d.file("new.db"), {d.file("part.db")}, stop_at_second_row),
               demcal::db::DbError);
  EXPECT_GT(asked, 2);
  EXPECT_EQ(names_in(d.path.string()), std::vector<std::string>{"part.db"});
  // An existing destination keeps what it had.
  write_db(d.file("dest.db"), {{"pending"}, {"pending"}, {"pending"}});
  asked = 0;
  EXPECT_THROW(demcal::db::merge_databases(d.file("dest.db"), {d.file("part.db")}, stop_at_second_row),
               demcal::db::DbError);
  Store s(d.file("dest.db"), /*read_only=*/true);
  EXPECT_EQ(status_of(s, "a"), "pending");
}

TEST(Merge, AMergeKilledPartWayLeavesNoDatabaseUnderTheDestinationsName) {
  TempDir d;
  write_db(d.file("part.db"), {{"done", 1.0}, {"failed"}, {"done", 3.0}});
  const std::string into = d.file("merged.db");
  const pid_t pid = fork();
  if (pid == 0) {  // killed (SIGKILL: nothing runs after it) at the second task row
    int asked = 0;
    demcal::db::merge_databases(into, {d.file("part.db")}, [&] {
      if (++asked == 3) raise(SIGKILL);
      return false;
    });
    _exit(0);
  }
  int st = 0;
  waitpid(pid, &st, 0);
  ASSERT_TRUE(WIFSIGNALED(st));
  EXPECT_FALSE(std::filesystem::exists(into)) << "an empty database would pass for the merged one";
  // What it leaves is named for what it is, and a rerun makes the destination whole.
  bool part_left = false;
  for (const auto& n : names_in(d.path.string())) part_left |= n.rfind("merged.db.merging-", 0) == 0;
  EXPECT_TRUE(part_left);
  const MergeReport r = demcal::db::merge_databases(into, {d.file("part.db")});
  EXPECT_EQ(r.tasks_added, 3);
  Store s(into, /*read_only=*/true);
  EXPECT_EQ(status_of(s, "a"), "done");
  EXPECT_EQ(x_of(s, "c"), 3.0);
}

TEST(Merge, ANewDestinationIsOneWholeFileWithNoJournalBeside) {
  TempDir d;
  write_db(d.file("part.db"), {{"done", 1.0}, {"failed"}, {"done", 3.0}});
  demcal::db::merge_databases(d.file("new.db"), {d.file("part.db")});
  // The rows are in the file itself, not in a -wal a rename would leave behind.
  EXPECT_EQ(names_in(d.path.string()), (std::vector<std::string>{"new.db", "part.db"}));
  Store s(d.file("new.db"), /*read_only=*/true);
  EXPECT_EQ(x_of(s, "a"), 1.0);
}
