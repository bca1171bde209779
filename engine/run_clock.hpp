#pragma once
// Wall and CPU time of a scene's run. The CPU time is the whole process's, every
// engine thread counted: a worker runs one task in a process of its own, so this is
// what the task cost in core-seconds whatever its thread count, the yardstick a
// forecast of later tasks needs (jobs/work_forecast).
#include <chrono>
#include <ctime>

namespace demcal::engine {

class RunClock {
 public:
  RunClock() : wall0_(std::chrono::steady_clock::now()), cpu0_(process_cpu_seconds()) {}
  double wall_seconds() const {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0_).count();
  }
  double cpu_seconds() const { return process_cpu_seconds() - cpu0_; }

 private:
  static double process_cpu_seconds() {
    timespec ts{};
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
  }
  std::chrono::steady_clock::time_point wall0_;
  double cpu0_;
};

}  // namespace demcal::engine
