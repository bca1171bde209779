#pragma once
// SIGINT/SIGTERM/SIGHUP as a polite stop request for a run loop (local runner and MPI
// rank 0): the handler only records the signal; the loop finishes cleanly.

#include <string>

namespace demcal::jobs {

// Installs the handlers for its lifetime (and clears any earlier request). A guard
// made while another is alive changes nothing: the outer one's request stands.
class StopSignalGuard {
 public:
  StopSignalGuard();
  ~StopSignalGuard();
  StopSignalGuard(const StopSignalGuard&) = delete;
  StopSignalGuard& operator=(const StopSignalGuard&) = delete;

 private:
  struct Saved;
  Saved* saved_;
};

// The signal received while a guard was installed, 0 if none.
int stop_signal();
// "interrupted (SIGINT)", "terminated (SIGTERM)", "hung up (SIGHUP: ...)".
std::string stop_signal_words(int sig);

}  // namespace demcal::jobs
