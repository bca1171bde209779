// Beyond one machine without MPI: sharded runs, merge, and the SLURM script.
#include "dist_util.hpp"

using namespace demcal::test;

namespace {

const std::vector<double> kFactors = {0.05, 0.07, 0.09, 0.11, 0.13, 0.15, 0.17};  // 7 tasks: shards of 3, 2, 2

// The unsharded reference run, and the three shards, in d.
void run_reference_and_shards(const TempDir& d) {
  write(d.file("j.json"), collision_job("grid", kFactors));
  const Result full = run_demcal({"run", "j.json", "--db", "full.db", "--workers", "2"}, d.path.string());
  ASSERT_EQ(full.rc, 0) << full.err;
  for (int i = 1; i <= 3; ++i) {
    const std::string part = "part-" + std::to_string(i) + ".db";
    const Result r = run_demcal({"run", "j.json", "--shard", std::to_string(i) + "/3", "--db", part}, d.path.string());
    ASSERT_EQ(r.rc, 0) << r.err;
  }
}

}  // namespace

TEST(Distribute, ShardsPlusMergeEqualUnshardedRun) {
  TempDir d;
  run_reference_and_shards(d);
  // Each shard holds exactly its round-robin slice, at the job's own indices.
  for (int i = 1; i <= 3; ++i) {
    const auto rows = tasks_of(d.file("part-" + std::to_string(i) + ".db"), "grid");
    ASSERT_EQ(rows.size(), i == 1 ? 3u : 2u);
    for (const auto& t : rows) {
      EXPECT_EQ(t.index % 3, i - 1);
      EXPECT_EQ(t.status, "done");
    }
  }
  // HDF5 files of different shards never collide: one folder per shard.
  EXPECT_TRUE(fs::is_directory(d.path / "demcal-out" / "grid" / "shard-1-of-3"));
  EXPECT_TRUE(fs::is_directory(d.path / "demcal-out" / "grid" / "shard-3-of-3"));
  // A shard resumes like any run: nothing is run twice.
  const Result again = run_demcal({"run", "j.json", "--shard", "2/3", "--db", "part-2.db"}, d.path.string());
  EXPECT_EQ(again.rc, 0) << again.err;
  EXPECT_NE(again.err.find("2 of 2 task(s) already done"), std::string::npos) << again.err;
  // A part started as a copy of the main database (docs/scaling.md) holds the whole
  // job: the shard counts its own tasks, not the job's 7.
  fs::copy_file(d.file("full.db"), d.file("copy-1.db"));
  const Result copy = run_demcal({"run", "j.json", "--shard", "1/3", "--db", "copy-1.db"}, d.path.string());
  EXPECT_EQ(copy.rc, 0) << copy.err;
  EXPECT_NE(copy.err.find("3 of 3 task(s) already done"), std::string::npos) << copy.err;
  EXPECT_NE(copy.err.find("3 done (3 reused), 0 failed, 0 unfinished, of 3"), std::string::npos) << copy.err;
  // ... and its table shows those three (indices 0, 3, 6: the table's first column is
  // the task id, one more than the index here), not the job's seven.
  EXPECT_EQ(std::count(copy.out.begin(), copy.out.end(), '\n'), 1 + 3 + 1) << copy.out;  // header, rows, hint
  for (const char* id : {"\n1 ", "\n4 ", "\n7 "}) EXPECT_NE(copy.out.find(id), std::string::npos) << id << copy.out;

  const Result m = run_demcal({"merge", "part-1.db", "part-2.db", "part-3.db", "--into", "merged.db"}, d.path.string());
  ASSERT_EQ(m.rc, 0) << m.err;
  EXPECT_NE(m.out.find("7 task(s) added"), std::string::npos) << m.out;
  EXPECT_NE(m.out.find("0 conflict(s)"), std::string::npos) << m.out;
  EXPECT_GT(expect_same_results(d.file("full.db"), d.file("merged.db"), "grid"), 7 * 3);
  // Series references come along, pointing at files that exist.
  demcal::db::Store merged(d.file("merged.db"), true);
  for (const auto& t : merged.tasks("grid")) {
    const auto arts = merged.artifacts(t.id);
    ASSERT_EQ(arts.size(), 1u);
    EXPECT_EQ(arts[0].first, "hdf5");
    EXPECT_TRUE(fs::exists(arts[0].second)) << arts[0].second;
  }
  // The merged database reads like an unsharded one.
  const Result st = run_demcal({"status", "--db", "merged.db"}, d.path.string());
  EXPECT_EQ(st.rc, 0) << st.err;
}

TEST(Distribute, MergingTheSamePartTwiceChangesNothing) {
  TempDir d;
  run_reference_and_shards(d);
  ASSERT_EQ(run_demcal({"merge", "part-1.db", "part-2.db", "--into", "m.db"}, d.path.string()).rc, 0);
  const std::string before = dump(d.file("m.db"));
  const Result r = run_demcal({"merge", "part-2.db", "part-1.db", "part-2.db", "--into", "m.db"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(r.out.find("0 task(s) added, 0 result(s) taken, 7 identical"), std::string::npos) << r.out;
  EXPECT_EQ(dump(d.file("m.db")), before);
  // Merging into a database that already ran the whole job: all identical, nothing changes.
  const std::string full = dump(d.file("full.db"));
  const Result f = run_demcal({"merge", "part-1.db", "part-2.db", "part-3.db", "--into", "full.db"}, d.path.string());
  EXPECT_EQ(f.rc, 0) << f.err;
  EXPECT_NE(f.out.find("7 identical"), std::string::npos) << f.out;
  EXPECT_EQ(dump(d.file("full.db")), full);
}

TEST(Distribute, ConflictIsReportedAndNotOverwritten) {
  TempDir d;
  run_reference_and_shards(d);
  fs::copy_file(d.file("part-2.db"), d.file("tampered.db"));
  sql(d.file("tampered.db"),
      "UPDATE metrics SET value = value + 1 WHERE rowid = (SELECT min(rowid) FROM metrics WHERE value IS NOT NULL"
      " AND name NOT LIKE 'wall_s%' AND name != 'cpu_s' AND name != 'particle_steps_per_s')");
  ASSERT_EQ(run_demcal({"merge", "part-2.db", "--into", "m.db"}, d.path.string()).rc, 0);
  const std::string before = dump(d.file("m.db"));
  const Result r = run_demcal({"merge", "tampered.db", "part-3.db", "--into", "m.db"}, d.path.string());
  EXPECT_EQ(r.rc, 1);
  EXPECT_NE(r.out.find("1 conflict(s)"), std::string::npos) << r.out;
  EXPECT_NE(r.err.find("conflict: tampered.db: task key"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("(destination) vs"), std::string::npos) << r.err;
  // The destination kept its own result; the other part's tasks were merged.
  EXPECT_EQ(tasks_of(d.file("m.db"), "grid").size(), 4u);
  demcal::db::Store m(d.file("m.db"), true), p2(d.file("part-2.db"), true);
  for (const auto& t : p2.tasks("grid")) {
    const auto row = m.tasks("grid");
    auto it = std::find_if(row.begin(), row.end(), [&](const auto& x) { return x.key == t.key; });
    ASSERT_NE(it, row.end());
    const auto a = m.metrics(it->id), b = p2.metrics(t.id);
    ASSERT_EQ(a.size(), b.size());
    for (std::size_t k = 0; k < a.size(); ++k)
      EXPECT_TRUE(same_bits(a[k].second, b[k].second) || std::isnan(a[k].second)) << a[k].first;
  }
}

TEST(Distribute, MergeRefusesForeignOrOtherSchemaDatabasesWritingNothing) {
  TempDir d;
  run_reference_and_shards(d);
  write(d.file("text.db"), "not a database at all, just some text that is long enough");
  sql(d.file("foreign.db"), "CREATE TABLE x(a); INSERT INTO x VALUES(1);");
  fs::copy_file(d.file("part-1.db"), d.file("future.db"));
  sql(d.file("future.db"), "PRAGMA user_version = 99");
  fs::copy_file(d.file("part-1.db"), d.file("older.db"));
  sql(d.file("older.db"), "PRAGMA user_version = 0");
  // A part from the demcal before heartbeats (schema 1: no runners table) merges.
  fs::copy_file(d.file("part-1.db"), d.file("v1.db"));
  sql(d.file("v1.db"), "DROP TABLE runners; PRAGMA user_version = 1");
  {
    const Result r1 = run_demcal({"merge", "v1.db", "--into", "from-v1.db"}, d.path.string());
    EXPECT_EQ(r1.rc, 0) << r1.err;
  }
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"text.db", "not a SQLite database"},
      {"foreign.db", "not a demcal one"},
      {"future.db", "schema version 99"},
      {"older.db", "schema version 0"},
      {"missing.db", "no such file"},
  };
  for (const auto& [bad, reason] : cases) {
    // A good part first: the bad one must stop the merge before anything is written.
    const Result r = run_demcal({"merge", "part-1.db", bad, "--into", "m.db"}, d.path.string());
    EXPECT_EQ(r.rc, 2) << bad << ": " << r.err;
    EXPECT_NE(r.err.find(bad), std::string::npos) << r.err;
    EXPECT_NE(r.err.find(reason), std::string::npos) << bad << ": " << r.err;
    EXPECT_FALSE(fs::exists(d.file("m.db"))) << bad;
  }
  // The destination itself must be a demcal database too.
  const Result r = run_demcal({"merge", "part-1.db", "--into", "foreign.db"}, d.path.string());
  EXPECT_EQ(r.rc, 2) << r.err;
  EXPECT_NE(r.err.find("foreign.db"), std::string::npos) << r.err;
}

TEST(Distribute, MergeIsOneTransaction) {
  TempDir d;
  run_reference_and_shards(d);
  // part-3 claims the job "grid" was run from a different job file: the merge stops
  // after part-1 and part-2 were merged in the transaction, which is rolled back.
  fs::copy_file(d.file("part-3.db"), d.file("other-spec.db"));
  sql(d.file("other-spec.db"), "UPDATE jobs SET spec_json = '{\"name\": \"grid\"}'");
  ASSERT_EQ(run_demcal({"merge", "part-1.db", "--into", "m.db"}, d.path.string()).rc, 0);
  const std::string before = dump(d.file("m.db"));
  const Result r = run_demcal({"merge", "part-2.db", "other-spec.db", "--into", "m.db"}, d.path.string());
  EXPECT_EQ(r.rc, 2) << r.err;  // the parts' fault: bad input
  EXPECT_NE(r.err.find("different job file"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("nothing merged"), std::string::npos) << r.err;
  EXPECT_EQ(dump(d.file("m.db")), before);
  // Into a new destination, the clash is with the part merged before: named as such
  // (the destination does not exist yet).
  const Result fresh = run_demcal({"merge", "part-2.db", "other-spec.db", "--into", "new.db"}, d.path.string());
  EXPECT_EQ(fresh.rc, 2) << fresh.err;
  EXPECT_NE(fresh.err.find("than the job of that name in part-2.db, merged before it"), std::string::npos) << fresh.err;
  EXPECT_FALSE(fs::exists(d.file("new.db")));
  // A job file whose description alone was edited runs the same tasks, and `demcal run`
  // takes it as the same job: so does merge.
  fs::copy_file(d.file("part-3.db"), d.file("described.db"));
  sql(d.file("described.db"), "UPDATE jobs SET spec_json = json_set(spec_json, '$.description', 'edited')");
  const Result same = run_demcal({"merge", "part-2.db", "described.db", "--into", "m.db"}, d.path.string());
  EXPECT_EQ(same.rc, 0) << same.err;
}

TEST(Distribute, BadShardIsRejected) {
  TempDir d;
  write(d.file("j.json"), collision_job("grid", kFactors));
  for (const std::string bad : {"0/3", "4/3", "1/0", "3", "a/b", "1/3/4", "-1/3", "1/", "2/1", ""}) {
    const Result r = run_demcal({"run", "j.json", "--shard", bad, "--db", "x.db"}, d.path.string());
    EXPECT_EQ(r.rc, 2) << bad;
    EXPECT_NE(r.err.find("--shard"), std::string::npos) << bad << ": " << r.err;
    EXPECT_FALSE(fs::exists(d.file("x.db"))) << bad;
  }
  const Result r = run_demcal({"run", "j.json", "--shard", "4/3"}, d.path.string());
  EXPECT_NE(r.err.find("between 1 and N = 3"), std::string::npos) << r.err;
  // More shards than tasks: the extra shards are empty, and that is fine.
  const Result empty = run_demcal({"run", "j.json", "--shard", "9/9", "--db", "e.db"}, d.path.string());
  EXPECT_EQ(empty.rc, 0) << empty.err;
  EXPECT_TRUE(tasks_of(d.file("e.db"), "grid").empty());
}

TEST(Distribute, SlurmScriptStepsRunLocallyEqualUnshardedRun) {
  TempDir d;
  run_reference_and_shards(d);
  Result r = run_demcal({"slurm", "j.json", "--array", "3", "--partition", "short", "--time", "0:10:00", "--db",
                         "slurm.db", "--out", "job.slurm.sh"},
                        d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  const std::string text = slurp(d.file("job.slurm.sh"));
  EXPECT_NE(text.find("#SBATCH --partition=short"), std::string::npos) << text;
  EXPECT_NE(text.find("#SBATCH --time=0:10:00"), std::string::npos) << text;
  EXPECT_NE(text.find("--dependency=afterok:"), std::string::npos) << text;
  EXPECT_EQ(run_bash("bash -n job.slurm.sh", d.path.string()).rc, 0);

  // Submission with a stand-in sbatch that logs its arguments and answers a job id.
  fs::create_directories(d.path / "bin");
  write(d.file("bin/sbatch"),
        "#!/bin/bash\necho \"$*\" >> \"$SBATCH_LOG\"\nn=$(wc -l < \"$SBATCH_LOG\")\necho \"$((4000 + n));cluster\"\n");
  fs::permissions(d.file("bin/sbatch"), fs::perms::owner_all);
  const std::string path = d.file("bin") + ":" + std::getenv("PATH");
  r = run_bash("bash job.slurm.sh", d.path.string(), {{"PATH", path}, {"SBATCH_LOG", d.file("sbatch.log")}});
  ASSERT_EQ(r.rc, 0) << r.err;
  const std::string log = slurp(d.file("sbatch.log"));
  const std::string self = fs::canonical(d.file("job.slurm.sh")).string();
  EXPECT_NE(log.find("--parsable --array=1-3 " + self + " shard"), std::string::npos) << log;
  // The merge's log by job id, not %a (no array element there).
  const std::string parts_dir = fs::weakly_canonical(d.path / "parts").string();
  EXPECT_NE(log.find("--dependency=afterok:4001 --cpus-per-task=1 --output=" + parts_dir + "/slurm-%x-merge-%j.out " + self +
                     " merge"),
            std::string::npos)
      << log;
  EXPECT_NE(r.out.find("job 4001 (array 1-3)"), std::string::npos) << r.out;

  // What SLURM would run: each array element, then the merge.
  for (int i = 1; i <= 3; ++i) {
    r = run_bash("bash job.slurm.sh shard", d.path.string(), {{"SLURM_ARRAY_TASK_ID", std::to_string(i)}});
    ASSERT_EQ(r.rc, 0) << i << ": " << r.err;
  }
  EXPECT_NE(run_bash("bash job.slurm.sh shard", d.path.string()).rc, 0);  // outside an array job
  r = run_bash("bash job.slurm.sh merge", d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_TRUE(fs::exists(d.path / "parts" / "part-3.db"));
  EXPECT_GT(expect_same_results(d.file("full.db"), d.file("slurm.db"), "grid"), 7 * 3);

  // Bad options are refused before anything is written.
  r = run_demcal({"slurm", "j.json", "--array", "3", "--partition", "a\nb", "--out", "bad.sh"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_FALSE(fs::exists(d.file("bad.sh")));
  EXPECT_EQ(run_demcal({"slurm", "j.json", "--array", "0"}, d.path.string()).rc, 2);
  r = run_demcal({"slurm", "j.json", "--array", "3", "--db", "nodir/x.db", "--out", "bad.sh"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--db: the folder"), std::string::npos) << r.err;
  // A project folder with a blank, a '%' and a '"' in its name: the #SBATCH line
  // quotes it as sbatch parses directives (quotes group, backslash escapes, '%%' is
  // a literal '%' in --output), and the steps run there.
  const std::string odd = "my 100% \"runs\"";
  fs::create_directories(d.path / odd);
  r = run_demcal({"slurm", "j.json", "--array", "3", "--db", odd + "/x.db", "--out", "odd.sh"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  const std::string parts = fs::absolute(d.path / odd / "parts").string();
  const std::string want = "#SBATCH --output=\"" + parts.substr(0, parts.size() - (odd.size() + 6)) +
                           "my 100%% \\\"runs\\\"/parts/slurm-%x-%A_%a.out\"\n";
  EXPECT_NE(slurp(d.file("odd.sh")).find(want), std::string::npos) << want << "\n" << slurp(d.file("odd.sh"));
  r = run_bash("bash odd.sh shard", d.path.string(), {{"SLURM_ARRAY_TASK_ID", "2"}});
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_TRUE(fs::exists(d.path / odd / "parts" / "part-2.db"));
  // A backslash turns SLURM's --output patterns off and is dropped: refused.
  fs::create_directories(d.path / "a\\b");
  r = run_demcal({"slurm", "j.json", "--array", "3", "--db", "a\\b/x.db", "--out", "bs.sh"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("has a backslash in its path"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(d.file("bs.sh")));
  // A relative --demcal is written absolute: the script runs it from the database's folder.
  fs::create_directories(d.path / "sub");
  fs::copy_file(DEMCAL_BIN, d.file("sub/demcal"));
  r = run_demcal({"slurm", "j.json", "--array", "3", "--db", "slurm.db", "--demcal", "sub/demcal", "--out", "rel.sh"},
                 d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(slurp(d.file("rel.sh")).find("DEMCAL='" + fs::canonical(d.file("sub/demcal")).string() + "'"), std::string::npos);
  // A newline in the current folder's path, which relative options take on: refused
  // (it wrote a script that did not parse, and exited 0).
  const fs::path nl = d.path / "new\nline";
  fs::create_directories(nl);
  fs::copy_file(d.file("j.json"), nl / "j.json");
  r = run_demcal({"slurm", "j.json", "--array", "2", "--out", "nl.sh"}, nl.string());
  EXPECT_EQ(r.rc, 2) << r.err;
  EXPECT_NE(r.err.find("--db: "), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("a relative path takes the current folder's"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(nl / "nl.sh"));
}

TEST(Distribute, AnMpiTimeoutWithoutMpiIsRefused) {
  TempDir d;
  write(d.file("j.json"), collision_job("t", {0.1}));
  const Result r = run_demcal({"run", "j.json", "--mpi-timeout", "5"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--mpi-timeout: applies to an MPI run only"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(d.file("demcal.db")));
}

#ifndef DEMCAL_HAVE_MPI
TEST(Distribute, MpiFlagInABuildWithoutMpiSaysSo) {
  TempDir d;
  write(d.file("j.json"), collision_job("grid", kFactors));
  const Result r = run_demcal({"run", "j.json", "--mpi"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("built without MPI"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(d.file("demcal.db")));
}
#endif

TEST(Distribute, HelpForMergeAndSlurm) {
  TempDir d;
  for (const char* cmd : {"merge", "slurm"}) {
    const Result r = run_demcal({cmd, "--help"}, d.path.string());
    EXPECT_EQ(r.rc, 0) << cmd;
    EXPECT_NE(r.out.find("Usage"), std::string::npos) << cmd << r.out;
  }
  const Result r = run_demcal({"run", "--help"}, d.path.string());
  EXPECT_NE(r.out.find("--shard"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("--mpi"), std::string::npos) << r.out;
  EXPECT_EQ(run_demcal({"merge", "--into", "x.db"}, d.path.string()).rc, 2);  // no parts
}

TEST(Distribute, SlurmRefusesADestinationItCouldNotMergeInto) {
  // Found out after every shard has run, a bad destination would waste the allocation.
  TempDir d;
  write(d.file("j.json"), collision_job("sl", {0.1, 0.2}));
  write(d.file("text.db"), "not a database at all, but long enough to look like a file header..........");
  Result r = run_demcal({"slurm", "j.json", "--array", "2", "--db", "text.db"}, d.path.string());
  EXPECT_EQ(r.rc, 2) << r.err;
  EXPECT_NE(r.err.find("text.db"), std::string::npos) << r.err;
  fs::create_directories(d.path / "sub");
  write(d.file("sub/parts"), "a file where the parts folder would go");
  r = run_demcal({"slurm", "j.json", "--array", "2", "--db", "sub/x.db"}, d.path.string());
  EXPECT_EQ(r.rc, 2) << r.err;
  EXPECT_NE(r.err.find("is not a folder"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(d.file("demcal-sl.slurm.sh")));
}

namespace demcal::test {
namespace {

TEST(Distribute, AFailedShardsHintRepeatsItsShardAndOutput) {
  TempDir d;
  write(d.file("j.json"), collision_job("fl", {0.1, 3.0}));  // the second task fails (step past the critical one)
  const Result r = run_demcal({"run", "j.json", "--db", "p2.db", "--shard", "2/2", "--out", "o2"}, d.path.string());
  EXPECT_EQ(r.rc, 1) << r.err;
  EXPECT_NE(r.err.find("demcal run j.json --db p2.db --shard 2/2 --out o2 --retry-failed"), std::string::npos) << r.err;
  // The part holds half the job, and status says so (its own counts look complete).
  const Result st = run_demcal({"status", "--db", "p2.db"}, d.path.string());
  EXPECT_NE(st.out.find("fl: 1 of the job file's 2 task(s) are not in this database"), std::string::npos) << st.out;
  // Merged, the failed task is said, not only counted among what was taken.
  ASSERT_EQ(run_demcal({"run", "j.json", "--db", "p1.db", "--shard", "1/2", "--out", "o1"}, d.path.string()).rc, 0);
  const Result m = run_demcal({"merge", "p1.db", "p2.db", "--into", "all.db"}, d.path.string());
  EXPECT_EQ(m.rc, 0) << m.err;
  EXPECT_NE(m.out.find("job fl in all.db has tasks without a result: 1 failed (demcal status --db all.db says why"),
            std::string::npos)
      << m.out;
  const Result clean = run_demcal({"merge", "p1.db", "--into", "one.db"}, d.path.string());
  EXPECT_EQ(clean.out.find("without a result"), std::string::npos) << clean.out;
}

}  // namespace
}  // namespace demcal::test
