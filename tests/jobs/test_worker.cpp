// The worker's result file, read back by the runner: what a task process leaves
// behind is all the parent learns of it.
#include "../temp_dir.hpp"
#include "jobs/hdf5_writer.hpp"
#include "jobs/part_file.hpp"
#include "jobs/series_plot.hpp"
#include "jobs/worker.hpp"

#include <H5Cpp.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <stdexcept>
#include <csignal>
#include <sched.h>
#include <sys/mount.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

using demcal::jobs::parse_worker_result;

TEST(WorkerResult, NonFiniteMetricsSurviveTheJsonTrip) {
  const auto o = parse_worker_result(R"({"status": "done", "wall_s": 1.5,
      "metrics": [["drift", "inf"], ["neg", "-inf"], ["undefined", "nan"], ["phi", 31.25]],
      "artifacts": [["hdf5", "out/1.h5"]]})");
  ASSERT_TRUE(o);
  EXPECT_EQ(o->status, "done");
  EXPECT_EQ(o->wall_s, 1.5);
  ASSERT_EQ(o->metrics.size(), 4u);
  EXPECT_TRUE(std::isinf(o->metrics[0].second) && o->metrics[0].second > 0);
  EXPECT_TRUE(std::isinf(o->metrics[1].second) && o->metrics[1].second < 0);
  EXPECT_TRUE(std::isnan(o->metrics[2].second));
  EXPECT_EQ(o->metrics[3].second, 31.25);
  ASSERT_EQ(o->artifacts.size(), 1u);
  EXPECT_EQ(o->artifacts[0].second, "out/1.h5");
  EXPECT_TRUE(o->error.empty()) << "a clean finish carries no message";
}

TEST(WorkerResult, FinishedTaskKeepsItsWarningsAndFailedTaskItsReason) {
  const auto done = parse_worker_result(R"({"status": "done", "wall_s": 2, "metrics": [], "artifacts": [],
      "warnings": "not quasi-static: largest inertial number 0.0039 exceeds 0.001"})");
  ASSERT_TRUE(done);
  EXPECT_EQ(done->error, "warning: not quasi-static: largest inertial number 0.0039 exceeds 0.001");
  const auto failed = parse_worker_result(R"({"status": "failed", "wall_s": 2, "metrics": [], "artifacts": [],
      "error": "not_settled in stage collapse: ..."})");
  ASSERT_TRUE(failed);
  EXPECT_EQ(failed->status, "failed");
  EXPECT_EQ(failed->error, "not_settled in stage collapse: ...");
}

TEST(WorkerResult, TruncatedOrIncompleteFileIsNoResult) {
  // A worker killed mid-write, or a file of another shape: the runner must treat
  // the task as failed without a result, not read half a record.
  EXPECT_FALSE(parse_worker_result(R"({"status": "done", "wall_s": 1.5, "metrics": [["phi", 3)"));
  EXPECT_FALSE(parse_worker_result(R"({"status": "done", "metrics": [], "artifacts": []})"));  // no wall_s
  EXPECT_FALSE(parse_worker_result(""));
  EXPECT_FALSE(parse_worker_result(R"({"status": "done", "wall_s": 1, "metrics": [[1, 2]], "artifacts": []})"));
}

namespace demcal::jobs {
namespace {

// A two-row series to write into task files.
engine::Series energy_series() {
  engine::Series s;
  s.name = "energy";
  s.columns = {"time", "total"};
  s.units = {"s", "J"};
  s.rows = {{0.0, 1.0}, {1.0, 1.0}};
  return s;
}

TEST(TaskFile, AFailedWriteSaysWhereAndWhyAndLeavesNothingThatLooksWhole) {
  demcal::test::TempDir d;
  const engine::Series s = energy_series();
  // Written whole: the key and id are in it, no .part is left beside it.
  const std::string ok = d.file("1-abcdef01.h5");
  write_task_hdf5(ok, {"collision", "abcdef0123456789", 1, "failed", "unstable in stage run: energy grew"}, {{"seed", 1}}, {s}, {});
  EXPECT_EQ(read_task_key(ok), "abcdef0123456789");
  EXPECT_EQ(read_series(ok, "energy").rows.size(), 2u);
  for (const auto& e : std::filesystem::directory_iterator(d.path))
    EXPECT_EQ(e.path().extension(), ".h5") << "left beside it: " << e.path();
  {  // a failed run's file says so, with the reason
    H5::H5File f(ok, H5F_ACC_RDONLY);
    std::string status, message;
    H5::Attribute a = f.openAttribute("status"), m = f.openAttribute("message");
    a.read(a.getStrType(), status);
    m.read(m.getStrType(), message);
    EXPECT_EQ(status, "failed");
    EXPECT_EQ(message, "unstable in stage run: energy grew");
  }
  // The file cannot be made (its folder is gone): an exception naming the path, not
  // an abort, and no file at the path.
  const std::string bad = d.file("gone/2-abcdef02.h5");
  try {
    write_task_hdf5(bad, {"collision", "abcdef0223456789", 2, "done", ""}, {}, {s}, {});
    FAIL() << "no exception";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("cannot write the HDF5 file " + bad), std::string::npos) << e.what();
  }
  EXPECT_FALSE(std::filesystem::exists(bad));
}

// A damaged task file is read with the reason: HDF5 alone says "H5Fopen failed",
// whether the file was cut short or is not HDF5 at all.
TEST(TaskFile, ADamagedFileIsNamedWithWhatIsWrongWithIt) {
  demcal::test::TempDir d;
  const engine::Series s = energy_series();
  const std::string f = d.file("1-abcdef01.h5");
  write_task_hdf5(f, {"collision", "abcdef0123456789", 1, "done", ""}, {{"seed", 1}}, {s}, {});
  const auto size = std::filesystem::file_size(f);
  auto error_of = [&](auto&& read) {
    try {
      read();
    } catch (const std::runtime_error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  std::filesystem::resize_file(f, size / 2);
  EXPECT_NE(error_of([&] { read_series(f, "energy"); }).find("an HDF5 file that cannot be read (" +
                                                             std::to_string(size / 2) + " bytes): cut short, damaged"),
            std::string::npos);
  std::ofstream(f, std::ios::trunc) << std::string(4000, 'x');
  EXPECT_NE(error_of([&] { read_task_key(f); }).find("cannot read " + f + ": not an HDF5 file (4000 bytes)"),
            std::string::npos);
  std::ofstream(f, std::ios::trunc).close();
  EXPECT_NE(error_of([&] { series_names(f); }).find(": an empty file"), std::string::npos);
}

// A disk that fills while the file is written (here a file-size limit, which makes
// write() fail as a full disk does): an exception naming the path and the likely
// cause, no crash, no .part left. HDF5 reports the failure when the file is closed,
// and a second close of that file (the C++ destructor's) crashed the worker with
// SIGSEGV. In a child process, so that the limit and a crash stay there.
TEST(TaskFile, AFullDiskMidWriteIsAnErrorNotACrash) {
  demcal::test::TempDir d;
  const std::string path = d.file("3-abcdef03.h5");
  engine::Series s;
  s.name = "energy";
  s.columns = {"t", "e"};
  for (int i = 0; i < 200000; ++i) s.rows.push_back({i * 1e-3, std::sin(i * 0.37)});  // ~3 MB, poorly compressible
  for (rlim_t limit : {rlim_t(8) << 10, rlim_t(64) << 10, rlim_t(512) << 10}) {
    const pid_t pid = fork();
    if (pid == 0) {
      std::signal(SIGXFSZ, SIG_IGN);  // write() then fails with EFBIG instead of killing
      const rlimit lim{limit, limit};
      if (setrlimit(RLIMIT_FSIZE, &lim) != 0) _exit(3);
      try {
        write_task_hdf5(path, {"collision", "abcdef0323456789", 3, "done", ""}, {}, {s}, {});
      } catch (const std::runtime_error& e) {
        const bool named = std::string(e.what()).find("cannot write the HDF5 file " + path) != std::string::npos;
        _exit(named ? 0 : 4);
      }
      _exit(5);  // written whole within the limit: the test's premise failed
    }
    int st = 0;
    ASSERT_EQ(waitpid(pid, &st, 0), pid);
    ASSERT_TRUE(WIFEXITED(st)) << "limit " << limit << ": killed by signal " << WTERMSIG(st);
    EXPECT_EQ(WEXITSTATUS(st), 0) << "limit " << limit << " (4: message without the path, 5: no error)";
    EXPECT_FALSE(std::filesystem::exists(path)) << "limit " << limit;
    for (const auto& e : std::filesystem::directory_iterator(d.path))
      EXPECT_EQ(e.path().extension(), ".h5") << "limit " << limit << ": left behind: " << e.path();
  }
}

// A disk that the task's own file fills: once the failed part file is removed there
// is room again, so a check made after the removal found the folder fine, failed the
// task (its metrics discarded) and let every later task run and fail alike. The
// folder is judged while the part is still there. A 512 KiB tmpfs in a mount
// namespace of a child process; skipped where mounting is not allowed.
TEST(TaskFile, ADiskFilledByTheTasksOwnFileIsTheFoldersFault) {
  demcal::test::TempDir d;
  const std::filesystem::path dir = d.path / "small-disk";
  std::filesystem::create_directories(dir);
  const std::string path = (dir / "4-abcdef04.h5").string();
  const std::string err_file = d.file("stderr.txt");
  engine::Series s;
  s.name = "energy";
  s.columns = {"t", "e"};
  for (int i = 0; i < 200000; ++i) s.rows.push_back({i * 1e-3, std::sin(i * 0.37)});  // ~3 MB, poorly compressible
  const pid_t pid = fork();
  if (pid == 0) {
    if (unshare(CLONE_NEWNS) != 0 || mount(nullptr, "/", nullptr, MS_REC | MS_PRIVATE, nullptr) != 0 ||
        mount("tmpfs", dir.c_str(), "tmpfs", 0, "size=512k") != 0)
      _exit(77);
    if (!freopen(err_file.c_str(), "w", stderr)) _exit(3);
    try {
      write_task_hdf5(path, {"collision", "abcdef0423456789", 4, "done", ""}, {}, {s}, {});
    } catch (const OutputWriteError& e) {
      if (!e.folder_full()) _exit(4);
      if (!folder_takes_a_file(dir)) _exit(6);  // the premise: room again once the part is gone
      if (!std::filesystem::is_empty(dir)) _exit(7);  // nothing left behind
      _exit(0);
    }
    _exit(5);
  }
  int st = 0;
  ASSERT_EQ(waitpid(pid, &st, 0), pid);
  ASSERT_TRUE(WIFEXITED(st)) << "killed by signal " << WTERMSIG(st);
  if (WEXITSTATUS(st) == 77) GTEST_SKIP() << "cannot mount a tmpfs here (needs CAP_SYS_ADMIN)";
  EXPECT_EQ(WEXITSTATUS(st), 0) << "4: not judged the folder's fault, 5: no error, 6: no room after the part went, "
                                   "7: a file left behind";
  std::ifstream f(err_file);
  const std::string err((std::istreambuf_iterator<char>(f)), {});
  EXPECT_EQ(err.find("H5Dclose"), std::string::npos) << "a destructor's line on stderr: " << err;
}

// A worker that ran its task but cannot write the result (a full disk; here a
// folder in the way of the file) exits with its own status, leaves no .tmp, and the
// parent's message says what happened instead of "without a result".
TEST(WorkerResult, AResultThatCannotBeWrittenIsNamedAndLeavesNoTmp) {
  demcal::test::TempDir d;
  WorkerTask t;
  t.task_id = 1;
  t.scene = "no-such-scene";  // fails at once: the result still has to be written
  t.h5_path = d.file("1.h5");
  t.result_path = d.file("r.json");
  std::filesystem::create_directories(t.result_path + ".tmp");  // the .tmp cannot be opened as a file
  EXPECT_EQ(run_worker(t), kWorkerResultUnwritable);
  std::filesystem::remove(t.result_path + ".tmp");
  std::filesystem::create_directories(t.result_path);  // now the rename fails
  EXPECT_EQ(run_worker(t), kWorkerResultUnwritable);
  EXPECT_FALSE(std::filesystem::exists(t.result_path + ".tmp"));
  const pid_t pid = fork();
  if (pid == 0) _exit(kWorkerResultUnwritable);
  int st = 0;
  ASSERT_EQ(waitpid(pid, &st, 0), pid);
  const std::string why = worker_failure(st, t.result_path);
  EXPECT_NE(why.find("could not write its result to " + t.result_path + ": the metrics are lost (disk full"),
            std::string::npos)
      << why;
  // The folder gone, or a file in its place: said, not "free space".
  const std::string in_gone = d.file("gone/r.json");
  EXPECT_NE(worker_failure(st, in_gone).find("(the folder is gone"), std::string::npos) << worker_failure(st, in_gone);
  std::ofstream(d.file("plain")) << "x";
  const std::string in_file = d.file("plain/r.json");
  EXPECT_NE(worker_failure(st, in_file).find("(something else than a folder is at its path now"), std::string::npos)
      << worker_failure(st, in_file);
  const pid_t other = fork();
  if (other == 0) _exit(7);
  ASSERT_EQ(waitpid(other, &st, 0), other);
  EXPECT_EQ(worker_failure(st, t.result_path), "worker exited with status 7 without a result");
}

}  // namespace
}  // namespace demcal::jobs

namespace {
void write_text(const std::string& path, const std::string& text) {
  std::ofstream(path, std::ios::binary | std::ios::trunc) << text;
}
std::string read_text(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), {});
}
}  // namespace

// gnuplot exits 0 when its write fails (a full disk): a PNG without its IEND chunk
// or an SVG without its end must not replace the earlier whole chart.
TEST(ImageFile, ACutShortImageIsRefusedAndTheEarlierOneKept) {
  demcal::test::TempDir d;
  const std::string png = d.file("chart.png");
  const std::string whole_png = std::string("\x89PNG\r\n\x1a\n", 8) + "...pixels..." +
                                std::string("\0\0\0\0IEND\xae\x42\x60\x82", 12);
  write_text(png, whole_png);
  {
    demcal::jobs::ImageFile image(png);
    write_text(image.part(), whole_png.substr(0, whole_png.size() - 20));  // cut short
    try {
      image.commit();
      FAIL() << "a cut-short PNG was committed";
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find("is cut short"), std::string::npos) << e.what();
    }
  }
  EXPECT_EQ(read_text(png), whole_png) << "the earlier chart is kept";
  {
    demcal::jobs::ImageFile image(png);
    write_text(image.part(), whole_png + "");
    image.commit();
  }
  const std::string svg = d.file("chart.svg");
  {
    demcal::jobs::ImageFile image(svg);
    write_text(image.part(), "<svg><g></g>");
    EXPECT_THROW(image.commit(), std::runtime_error);
  }
  EXPECT_FALSE(std::filesystem::exists(svg));
  {
    demcal::jobs::ImageFile image(svg);
    write_text(image.part(), "<svg><g></g></svg>\n");
    image.commit();
  }
  EXPECT_TRUE(std::filesystem::exists(svg));
  for (const auto& e : std::filesystem::directory_iterator(d.path))
    EXPECT_EQ(e.path().filename().string().find(".part"), std::string::npos) << "left behind: " << e.path();
}
