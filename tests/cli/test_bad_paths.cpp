// Paths and files that are not what they look like: names SQLite reads as something
// else, control characters, bytes that are not UTF-8, devices, damaged databases,
// files that cannot be job files. Each is refused (exit 2) naming the option or the
// field, before anything is written.
#include "cli_util.hpp"
#include "dist_util.hpp"

using namespace demcal::test;

namespace {

// A demcal database with one finished collision job, and a foreign one.
void two_databases(const TempDir& d) {
  write(d.file("j.json"), collision_job("small", {0.1}));
  ASSERT_EQ(run_demcal({"run", "j.json", "--db", "ok.db"}, d.path.string()).rc, 0);
  sql(d.file("other.db"), "CREATE TABLE t(x); INSERT INTO t VALUES(42);");
}

}  // namespace

TEST(BadPaths, DatabaseNamesSqliteWouldNotReadAsTheFileAreRefused) {
  TempDir d;
  two_databases(d);
  const std::string other = dump(d.file("other.db")), ok = dump(d.file("ok.db"));
  // "file:..." is a URI to SQLite: it would open other.db behind the checks' back.
  Result r = run_demcal({"run", "j.json", "--db", "file:other.db"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--db: \"file:other.db\" would be read by SQLite as a URI"), std::string::npos) << r.err;
  r = run_demcal({"merge", "ok.db", "--into", "FILE:other.db"}, d.path.string());
  EXPECT_EQ(r.rc, 2) << r.err;
  EXPECT_EQ(dump(d.file("other.db")), other);
  // ":memory:" would lose every result at exit.
  r = run_demcal({"run", "j.json", "--db", ":memory:"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--db: \":memory:\" is a database in memory"), std::string::npos) << r.err;
  EXPECT_EQ(run_demcal({"merge", "ok.db", "--into", ":memory:"}, d.path.string()).rc, 2);
  // A device reads as an empty file.
  r = run_demcal({"run", "j.json", "--db", "/dev/null"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("/dev/null is not a regular file"), std::string::npos) << r.err;
  EXPECT_EQ(run_demcal({"merge", "ok.db", "--into", "/dev/null"}, d.path.string()).rc, 2);
  EXPECT_EQ(run_demcal({"merge", "ok.db", "--into", ""}, d.path.string()).rc, 2);
  // ./file:x.db is a plain file name, and works.
  r = run_demcal({"merge", "ok.db", "--into", "./file:copy.db"}, d.path.string());
  EXPECT_EQ(r.rc, 0) << r.err;
  EXPECT_TRUE(fs::exists(d.file("file:copy.db")));
  EXPECT_EQ(dump(d.file("ok.db")), ok);
}

TEST(BadPaths, ControlCharactersAndNonUtf8AreRefusedBeforeAnythingRuns) {
  TempDir d;
  two_databases(d);
  // A newline would end a line of the gnuplot or batch script the path is written into.
  Result r = run_demcal({"map", "--db", "ok.db", "--metric", "max_relative_error", "--out",
                         "a\nsystem \"touch INJECTED\"\nb.png"},
                        d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--out: the path contains a control character"), std::string::npos) << r.err;
  r = run_demcal({"slurm", "j.json", "--array", "2", "--out", "s.sh", "--parts", "/x/p\ntouch INJECTED\n#"},
                 d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--parts: the path contains a control character"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(d.file("s.sh")));
  EXPECT_FALSE(fs::exists(d.file("INJECTED")));
  // Paths go into JSON records, which must be UTF-8: refused before a task runs.
  r = run_demcal({"run", "j.json", "--db", "new.db", "--out", "out\xff"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--out: the path is not valid UTF-8"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(d.file("new.db")));
  EXPECT_EQ(run_demcal({"run", "j.json", "--db", "d\xff.db"}, d.path.string()).rc, 2);
  // Overlong forms, surrogates and code points past U+10FFFF are not UTF-8 either.
  for (const char* bad : {"ov\xc0\xaf", "sur\xed\xa0\x80", "big\xf5\x80\x80\x80", "cut\xe2\x82"})
    EXPECT_EQ(run_demcal({"run", "j.json", "--db", "new.db", "--out", bad}, d.path.string()).rc, 2) << bad;
  EXPECT_FALSE(fs::exists(d.file("new.db")));
  // Well-formed UTF-8 (and blanks) work.
  const Result ok = run_demcal({"run", "j.json", "--db", "ok.db", "--out", "résultats \xe2\x82\xac \xf0\x9f\x8c\x8a"},
                               d.path.string());
  EXPECT_EQ(ok.rc, 0) << ok.err;
  // map's --out may not be empty either.
  EXPECT_EQ(run_demcal({"map", "--db", "ok.db", "--metric", "max_relative_error", "--out", ""}, d.path.string()).rc, 2);
}

TEST(BadPaths, AFileInTheWayOfTheJobsOutputFolderLeavesTheDatabaseAsItWas) {
  TempDir d;
  two_databases(d);
  fs::create_directories(d.path / "out");
  write(d.file("out/small"), "in the way");
  const std::string ok = dump(d.file("ok.db"));
  Result r = run_demcal({"run", "j.json", "--db", "new.db", "--out", "out"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--out: cannot create the output folder"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(d.file("new.db")));
  write(d.file("j2.json"), collision_job("small2", {0.2}));
  write(d.file("out/small2"), "in the way");
  r = run_demcal({"run", "j2.json", "--db", "ok.db", "--out", "out"}, d.path.string());
  EXPECT_EQ(r.rc, 2) << r.err;
  EXPECT_EQ(dump(d.file("ok.db")), ok);
}

TEST(BadPaths, NonFiniteNumbersInOptionsAreRefused) {
  TempDir d;
  two_databases(d);
  // inf matched every task (|a - inf| <= 1e-12 inf), nan none.
  for (const char* v : {"inf", "-inf", "1e999", "nan"}) {
    const Result r = run_demcal({"query", "--db", "ok.db", "--where", std::string("dt_factor=") + v}, d.path.string());
    EXPECT_EQ(r.rc, 2) << v;
    EXPECT_NE(r.err.find("--where: dt_factor is a finite number"), std::string::npos) << r.err;
  }
  Result r = run_demcal({"study", "timestep", "--quick", "--db", "s.db", "--tolerance", "nan"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--tolerance: must be a positive finite number"), std::string::npos) << r.err;
  r = run_demcal({"run", "j.json", "--db", "ok.db", "--mpi-timeout", "nan"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_FALSE(fs::exists(d.file("s.db")));
}

TEST(BadPaths, WholeNumbersInOptionsAreReadInDecimal) {
  TempDir d;
  two_databases(d);
  const std::string before = slurp(d.file("ok.db"));
  // CLI11 alone read 021 as octal 17, inside --refine's range, and 0x10 as 16.
  Result r = run_demcal({"fit", "--db", "ok.db", "--target", "phi_peak=40", "--refine", "021"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--refine: Value 21 not in range 0 to 20"), std::string::npos) << r.err;
  for (const char* v : {"0x10", "4.0", "2e1", "+-3", "", " 3"}) {
    r = run_demcal({"run", "j.json", "--db", "ok.db", "--workers", v}, d.path.string());
    EXPECT_EQ(r.rc, 2) << v;
    EXPECT_NE(r.err.find(std::string("must be a whole number in decimal digits, got \"") + v + "\""), std::string::npos)
        << v << ": " << r.err;
  }
  EXPECT_EQ(slurp(d.file("ok.db")), before);
  // Zeros in front and a plus sign change nothing.
  r = run_demcal({"slurm", "j.json", "--array", "010", "--cpus-per-task", "+02", "--db", "s.db", "--out", "s.sh"}, d.path.string());
  ASSERT_EQ(r.rc, 0) << r.err;
  const std::string text = slurp(d.file("s.sh"));
  EXPECT_NE(text.find("\nN=10\n"), std::string::npos) << text;
  EXPECT_NE(text.find("--cpus-per-task=2"), std::string::npos) << text;
}

TEST(BadPaths, TheCommandLinesOwnRefusalsReadLikeDemcals) {
  TempDir d;
  Result r = run_demcal({"run", "j.json", "--bogus"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_EQ(r.err.rfind("demcal: error: ", 0), 0u) << r.err;
  EXPECT_NE(r.err.find("--bogus"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("(demcal run --help lists the options)"), std::string::npos) << r.err;
  r = run_demcal({"run"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_EQ(r.err, "demcal: error: JOB is required\n(demcal run --help lists the options)\n");
  r = run_demcal({"frobnicate", "--db", "x.db"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_EQ(r.err.rfind("demcal: error: unknown command \"frobnicate\" (the commands: validate, run, status, ", 0), 0u) << r.err;
  r = run_demcal({}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_EQ(r.err, "demcal: error: A subcommand is required\n(demcal --help lists the options)\n");
  EXPECT_FALSE(fs::exists(d.file("demcal.db")));
}

// An empty name is a slip, not "no filter" (query --job '' listed every job) nor "the
// default" (plot --x '' drew the default column). (An empty item inside a list,
// "a,,b", CLI11 drops by itself.)
TEST(BadPaths, EmptyNamesInOptionsAreRefused) {
  TempDir d;
  const std::vector<std::vector<std::string>> cases = {
      {"query", "--job", ""},          {"status", "--job", ""},
      {"query", "--metrics", ""},
      {"map", "--metric", ""},         {"map", "--metric", "phi_peak", "--job", ""},
      {"envelope", "--job", ""},       {"fit", "--target", "phi_peak=40", "--job", ""},
      {"plot", "1", "--series", ""},   {"plot", "1", "--series", "energy", "--x", ""},
      {"plot", "1", "--series", "energy", "--y", ""},
  };
  for (const auto& args : cases) {
    const Result r = run_demcal(args, d.path.string());
    EXPECT_EQ(r.rc, 2) << args[0] << " " << args[1] << " " << args[2];
    EXPECT_NE(r.err.find(": must not be empty"), std::string::npos) << r.err;
  }
  EXPECT_TRUE(fs::is_empty(d.path / "out.stdout"));
}

TEST(BadPaths, ADamagedDemcalDatabaseIsRefusedUntouched) {
  TempDir d;
  two_databases(d);
  fs::copy_file(d.file("ok.db"), d.file("dropped.db"));
  sql(d.file("dropped.db"), "DROP TABLE metrics;");
  fs::copy_file(d.file("ok.db"), d.file("reset.db"));
  sql(d.file("reset.db"), "PRAGMA user_version = 0;");
  const std::string dropped = dump(d.file("dropped.db")), reset = dump(d.file("reset.db"));
  Result r = run_demcal({"run", "j.json", "--db", "dropped.db"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("dropped.db is a damaged demcal database: table metrics is missing"), std::string::npos) << r.err;
  r = run_demcal({"query", "--db", "reset.db"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("reset.db is a damaged demcal database: schema version 0"), std::string::npos) << r.err;
  EXPECT_EQ(dump(d.file("dropped.db")), dropped);
  EXPECT_EQ(dump(d.file("reset.db")), reset);
  // A column dropped: refused as damaged by every command, not a raw SQLite error
  // after a run wrote its runner row (exit 1, "once the database can be written").
  fs::copy_file(d.file("ok.db"), d.file("column.db"));
  sql(d.file("column.db"), "ALTER TABLE tasks DROP COLUMN wall_s;");
  const std::string column = dump(d.file("column.db"));
  for (const std::vector<std::string>& args : std::vector<std::vector<std::string>>{
           {"run", "j.json", "--db", "column.db"}, {"status", "--db", "column.db"}, {"query", "--db", "column.db"}}) {
    r = run_demcal(args, d.path.string());
    EXPECT_EQ(r.rc, 2) << args[0] << ": " << r.err;
    EXPECT_NE(r.err.find("column.db is a damaged demcal database: table tasks has no column wall_s"), std::string::npos)
        << args[0] << ": " << r.err;
  }
  EXPECT_EQ(dump(d.file("column.db")), column);
}

TEST(BadPaths, FilesThatCannotBeJobsAreRefused) {
  TempDir d;
  // Read up to a cap, not until memory runs out.
  Result r = run_demcal({"validate", "/dev/zero"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("/dev/zero: larger than 16 MiB"), std::string::npos) << r.err;
  // A NUL byte: everything after it would have been ignored.
  write(d.file("nul.json"), collision_job("n", {0.1}) + std::string(1, '\0') + " {{{ garbage");
  r = run_demcal({"validate", "nul.json"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("a NUL byte at offset"), std::string::npos) << r.err;
  // A stiffness that passes "> 0" but gives an infinite step.
  nlohmann::json j = nlohmann::json::parse(collision_job("soft", {0.1}));
  j["material"]["kn"] = 5e-324;
  write(d.file("soft.json"), j.dump());
  r = run_demcal({"validate", "soft.json"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("material.kn: task #0: the time step works out to inf s"), std::string::npos) << r.err;
  // A density that passes "> 0" but leaves the smallest grain no moment of inertia:
  // named, not read as every step past a critical step of 0 s.
  j = nlohmann::json::parse(collision_job("light", {0.1}));
  j["material"]["density"] = 1e-300;
  write(d.file("light.json"), j.dump());
  r = run_demcal({"validate", "light.json"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("material.density: task #0: the critical time step works out to 0 s"), std::string::npos) << r.err;
  write(d.file("light-tx.json"), R"({"name": "ltx", "scene": "triaxial", "fidelity": "quick",
                                     "triaxial": {"scaled_density": 1e-300}})");
  r = run_demcal({"validate", "light-tx.json"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("triaxial.scaled_density: task #0: the critical time step"), std::string::npos) << r.err;
  // A stiffness past what a double holds over the grain's mass: kn is named, not density.
  j = nlohmann::json::parse(collision_job("stiff", {0.1}));
  j["material"]["kn"] = 1e308;
  write(d.file("stiff.json"), j.dump());
  r = run_demcal({"validate", "stiff.json"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("material.kn: task #0: the critical time step works out to 0 s: kn over the smallest grain's mass"),
            std::string::npos) << r.err;
  // A column that would need billions of grains.
  write(d.file("big.json"), R"({"name": "big", "scene": "repose", "fidelity": "quick",
                                "repose": {"column_width": 10, "column_height": 10, "depth_diameters": 1000}})");
  r = run_demcal({"validate", "big.json"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("repose.column_width"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("million grains, more than this scene takes"), std::string::npos) << r.err;
}

TEST(BadPaths, AMergeThatFailsOnConflictingJobsLeavesNoDestinationBehind) {
  TempDir d;
  write(d.file("a.json"), collision_job("same", {0.1}));
  write(d.file("b.json"), collision_job("same", {0.2}));
  ASSERT_EQ(run_demcal({"run", "a.json", "--db", "a.db"}, d.path.string()).rc, 0);
  ASSERT_EQ(run_demcal({"run", "b.json", "--db", "b.db"}, d.path.string()).rc, 0);
  const Result r = run_demcal({"merge", "a.db", "b.db", "--into", "new.db"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("was run from a different job file"), std::string::npos) << r.err;
  for (const char* f : {"new.db", "new.db-wal", "new.db-shm"}) EXPECT_FALSE(fs::exists(d.file(f))) << f;
}

TEST(BadPaths, TheBatchScriptNeverReplacesTheDatabaseTheJobFileOrAnotherFile) {
  TempDir d;
  two_databases(d);
  const std::string ok = dump(d.file("ok.db")), job = slurp(d.file("j.json"));
  Result r = run_demcal({"slurm", "j.json", "--array", "2", "--db", "ok.db", "--out", "ok.db"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--out: ok.db is the database (--db)"), std::string::npos) << r.err;
  // A database not made yet: the script there would meet the merge after every shard ran.
  r = run_demcal({"slurm", "j.json", "--array", "2", "--db", "later.db", "--out", "later.db"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--out: later.db is the database (--db)"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(d.file("later.db")));
  r = run_demcal({"slurm", "j.json", "--array", "2", "--db", "ok.db", "--out", "./j.json"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("is the job file"), std::string::npos) << r.err;
  write(d.file("notes.txt"), "mine\n");
  r = run_demcal({"slurm", "j.json", "--array", "2", "--db", "ok.db", "--out", "notes.txt"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("exists and is not a script demcal wrote"), std::string::npos) << r.err;
  EXPECT_EQ(dump(d.file("ok.db")), ok);
  EXPECT_EQ(slurp(d.file("j.json")), job);
  EXPECT_EQ(slurp(d.file("notes.txt")), "mine\n");
  // Its own earlier script it replaces.
  ASSERT_EQ(run_demcal({"slurm", "j.json", "--array", "2", "--db", "ok.db", "--out", "s.sh"}, d.path.string()).rc, 0);
  r = run_demcal({"slurm", "j.json", "--array", "3", "--db", "ok.db", "--out", "s.sh"}, d.path.string());
  EXPECT_EQ(r.rc, 0) << r.err;
  EXPECT_NE(slurp(d.file("s.sh")).find("in 3 shard(s)"), std::string::npos);
  EXPECT_FALSE(fs::exists(d.file("s.sh.part")));
}

TEST(BadPaths, AJobFileMayNotTakeTheNameOfARefinementRound) {
  TempDir d;
  write(d.file("r.json"), collision_job("grid.refine7", {0.1}));
  const Result r = run_demcal({"validate", "r.json"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("name: \"grid.refine7\" ends in .refine<N>"), std::string::npos) << r.err;
  write(d.file("ok.json"), collision_job("grid.refined", {0.1}));
  EXPECT_EQ(run_demcal({"validate", "ok.json"}, d.path.string()).rc, 0);
}

TEST(BadPaths, ParametersNestedDeepInAnEditedDatabaseDoNotCrashTheReaders) {
  TempDir d;
  two_databases(d);
  sql(d.file("ok.db"), "UPDATE tasks SET params_json = '" + std::string(200000, '[') + std::string(200000, ']') + "'");
  for (const std::vector<std::string>& args :
       {std::vector<std::string>{"query", "--db", "ok.db", "--format", "json"}, {"query", "--db", "ok.db"},
        {"status", "--db", "ok.db"}}) {
    const Result r = run_demcal(args, d.path.string());
    EXPECT_LE(r.rc, 2) << args[0] << ": a crash, not an answer: " << r.err;
  }
  const Result r = run_demcal({"map", "--db", "ok.db", "--metric", "max_relative_error"}, d.path.string());
  EXPECT_LE(r.rc, 2) << r.err;
}

TEST(BadPaths, AnEditedTaskTheWorkForecastCannotReadFailsOnlyItself) {
  // The forecast `run` logs reads every pending task's stored parameters; one that an
  // edit broke must fail as a task (named), not end the run before anything runs.
  TempDir d;
  write(d.file("j.json"), collision_job("edited", {0.05, 0.1, 0.2}));
  ASSERT_EQ(run_demcal({"run", "j.json", "--db", "e.db"}, d.path.string()).rc, 0);
  sql(d.file("e.db"), "UPDATE tasks SET status = 'pending'");
  sql(d.file("e.db"), "UPDATE tasks SET params_json = '{\"seed\": 1}' WHERE id = 2");
  const Result r = run_demcal({"run", "j.json", "--db", "e.db"}, d.path.string());
  EXPECT_EQ(r.rc, 1) << r.err;
  EXPECT_NE(r.err.find("task 2"), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find("work of the"), std::string::npos) << r.err;
  int done = 0;
  for (const auto& t : tasks_of(d.file("e.db"), "edited")) done += t.status == "done";
  EXPECT_EQ(done, 2);
}

TEST(BadPaths, AStudyWhoseTableCannotBeWrittenSaysSoInsteadOfWrote) {
  TempDir d;
  fs::create_directories(d.path / "so" / "timestep.csv");  // a folder where the table goes
  const Result r = run_demcal({"study", "timestep", "--quick", "--db", "so.db", "--out", "so"}, d.path.string());
  EXPECT_EQ(r.rc, 1);
  EXPECT_NE(r.err.find("cannot move the file into place at so/timestep.csv"), std::string::npos) << r.err;
  EXPECT_TRUE(fs::is_directory(d.path / "so" / "timestep.csv")) << "what was in the way is left alone";
  EXPECT_EQ(r.out.find("wrote"), std::string::npos) << r.out;
}

TEST(BadPaths, AStudyWhoseFoldersCannotBeMadeMakesNoDatabase) {
  TempDir d;
  fs::create_directories(d.path / "o");
  write(d.file("o/tasks"), "in the way");
  const Result r = run_demcal({"study", "timestep", "--quick", "--db", "n.db", "--out", "o"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("--out: cannot create the folder o/tasks"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(d.file("n.db")));
}

TEST(BadPaths, ALinkLoopOrANameTooLongIsBadInputNamingThePath) {
  TempDir d;
  write(d.file("j.json"), collision_job("small", {0.1}));
  fs::create_symlink("loop2", d.path / "loop1");
  fs::create_symlink("loop1", d.path / "loop2");
  Result r = run_demcal({"status", "--db", "loop1"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("cannot use loop1: Too many levels of symbolic links"), std::string::npos) << r.err;
  r = run_demcal({"run", "j.json", "--db", "x.db", "--out", "loop1"}, d.path.string());
  EXPECT_EQ(r.rc, 2) << r.err;
  EXPECT_FALSE(fs::exists(d.file("x.db")));
  r = run_demcal({"status", "--db", std::string(5000, 'a') + ".db"}, d.path.string());
  EXPECT_EQ(r.rc, 2);
  EXPECT_NE(r.err.find("File name too long"), std::string::npos) << r.err.substr(0, 200);
}
