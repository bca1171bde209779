#include "gnuplot_process.hpp"

#include "child_process.hpp"
#include "job_error.hpp"
#include "progress.hpp"
#include "stop_signal.hpp"

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdlib>
#include <fcntl.h>
#include <sys/wait.h>
#include <thread>
#include <unistd.h>

namespace demcal::jobs {
namespace {

using Clock = std::chrono::steady_clock;

pid_t start_gnuplot(const std::string& script) {
  // Bound to demcal: out of demcal's group, a kill of that group (a closed terminal,
  // the OOM killer taking demcal) would not reach gnuplot.
  const pid_t pid = fork_bound_to_parent(127);
  if (pid < 0) throw std::runtime_error("cannot start gnuplot: fork failed");
  if (pid == 0) {
    // Its own group, so that stopping it reaches whatever it starts, and a terminal's
    // Ctrl-C reaches demcal, which decides.
    setpgid(0, 0);
    signal(SIGINT, SIG_DFL);
    signal(SIGTERM, SIG_DFL);
    signal(SIGPIPE, SIG_DFL);  // demcal ignores it; an ignored signal would stay so across exec
    const int null = open("/dev/null", O_RDONLY);
    if (null >= 0) dup2(null, STDIN_FILENO);  // a script that pauses for input fails instead of waiting
    execlp("gnuplot", "gnuplot", script.c_str(), static_cast<char*>(nullptr));
    _exit(127);
  }
  setpgid(pid, pid);  // also here: no window in which a signal to the group misses it
  return pid;
}

// Stops the group and reaps the child, so no gnuplot outlives the call.
void stop_gnuplot(pid_t pid, int sig) {
  kill(-pid, sig);
  int st = 0;
  for (int i = 0; i < 100; ++i) {  // up to 2 s to exit on SIGTERM, then SIGKILL
    if (waitpid(pid, &st, WNOHANG) == pid) return;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  kill(-pid, SIGKILL);
  while (waitpid(pid, &st, 0) < 0 && errno == EINTR) {
  }
}

}  // namespace

GnuplotInterrupted::GnuplotInterrupted(int signal)
    : std::runtime_error(stop_signal_words(signal) +
                         " while gnuplot was drawing: gnuplot stopped, nothing written"),
      signal_(signal) {}

double gnuplot_time_limit_s() {
  const char* env = std::getenv("DEMCAL_GNUPLOT_TIMEOUT_S");
  if (!env || !*env) return 300.0;
  char* end = nullptr;
  const double v = std::strtod(env, &end);
  if (*end != '\0' || !std::isfinite(v) || v <= 0)
    throw JobError("DEMCAL_GNUPLOT_TIMEOUT_S", std::string("must be a positive number of seconds, got '") + env + "'");
  return v;
}

bool gnuplot_on_path() {
  const char* path = std::getenv("PATH");
  std::string dirs = path ? path : "/usr/bin:/bin";  // execlp's default without PATH
  std::size_t from = 0;
  while (from <= dirs.size()) {
    const std::size_t to = std::min(dirs.find(':', from), dirs.size());
    const std::string dir = to > from ? dirs.substr(from, to - from) : ".";  // an empty entry is the current folder
    if (::access((dir + "/gnuplot").c_str(), X_OK) == 0) return true;
    from = to + 1;
  }
  return false;
}

void run_gnuplot_script(const std::string& script) {
  const double limit_s = gnuplot_time_limit_s();
  StopSignalGuard guard;  // nests inside map's, which covers its work between the passes
  if (stop_signal()) throw GnuplotInterrupted(stop_signal());
  const pid_t pid = start_gnuplot(script);
  const auto start = Clock::now();
  int st = 0;
  for (;;) {
    const pid_t r = waitpid(pid, &st, WNOHANG);
    if (r == pid) break;
    if (r < 0 && errno != EINTR) throw std::runtime_error("cannot wait for gnuplot");
    if (stop_signal()) {
      stop_gnuplot(pid, SIGTERM);
      throw GnuplotInterrupted(stop_signal());
    }
    if (std::chrono::duration<double>(Clock::now() - start).count() > limit_s) {
      stop_gnuplot(pid, SIGKILL);
      throw std::runtime_error("gnuplot did not finish within " + plain_number(limit_s) +
                               " s and was stopped (DEMCAL_GNUPLOT_TIMEOUT_S sets the limit)");
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  if (WIFSIGNALED(st))
    throw std::runtime_error("gnuplot was killed by signal " + std::to_string(WTERMSIG(st)) + " while drawing");
  if (!WIFEXITED(st) || WEXITSTATUS(st) == 127) throw std::runtime_error("cannot run gnuplot (is gnuplot installed?)");
  if (WEXITSTATUS(st) != 0) throw std::runtime_error("gnuplot failed (exit status " + std::to_string(WEXITSTATUS(st)) + ")");
}

}  // namespace demcal::jobs
