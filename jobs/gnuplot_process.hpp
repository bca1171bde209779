#pragma once
// gnuplot as a child process: run without a shell, in its own process group, with
// a time limit, and stopped with demcal when demcal is asked to stop.
#include <stdexcept>
#include <string>

namespace demcal::jobs {

// SIGINT or SIGTERM arrived while gnuplot drew: gnuplot (and anything it started)
// has been stopped and waited for; what it drew is a part file the caller drops.
class GnuplotInterrupted : public std::runtime_error {
 public:
  explicit GnuplotInterrupted(int signal);
  int signal() const { return signal_; }

 private:
  int signal_;
};

// gnuplot's time limit in seconds: DEMCAL_GNUPLOT_TIMEOUT_S when set to a positive
// number, else 300 (a chart takes seconds; a gnuplot that waits on something never
// comes back). Throws JobError (bad input, exit 2) naming the variable when it is not
// a positive number.
double gnuplot_time_limit_s();

// Whether an executable gnuplot is on PATH (where run_gnuplot_script's execlp looks):
// a study checks before it runs its tasks, not after.
bool gnuplot_on_path();

// Runs gnuplot on a script file, stdin from /dev/null. Throws std::runtime_error when
// gnuplot is missing, fails or outlives the time limit (then it is killed), and
// GnuplotInterrupted on SIGINT/SIGTERM.
void run_gnuplot_script(const std::string& script_path);

}  // namespace demcal::jobs
