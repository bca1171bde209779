#include "stop_signal.hpp"

#include <csignal>
#include <signal.h>

namespace demcal::jobs {
namespace {
volatile std::sig_atomic_t g_stop = 0;
int g_depth = 0;  // guards nest (map around its gnuplot passes); only the outermost installs
extern "C" void on_stop_signal(int sig) { g_stop = sig; }
}  // namespace

struct StopSignalGuard::Saved {
  struct sigaction old_int {}, old_term {}, old_hup {};
};

StopSignalGuard::StopSignalGuard() : saved_(nullptr) {
  if (g_depth++ > 0) return;  // an inner guard keeps the outer one's handlers and any request
  saved_ = new Saved;
  g_stop = 0;
  struct sigaction sa {};
  sa.sa_handler = on_stop_signal;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, &saved_->old_int);
  sigaction(SIGTERM, &sa, &saved_->old_term);
  // A closed terminal or SSH session (SIGHUP) stops the run as Ctrl-C does, tasks
  // back in the queue, unless the run was started to outlive it (nohup: ignored).
  sigaction(SIGHUP, nullptr, &saved_->old_hup);
  if (saved_->old_hup.sa_handler != SIG_IGN) sigaction(SIGHUP, &sa, nullptr);
}

StopSignalGuard::~StopSignalGuard() {
  --g_depth;
  if (!saved_) return;
  sigaction(SIGINT, &saved_->old_int, nullptr);
  sigaction(SIGTERM, &saved_->old_term, nullptr);
  sigaction(SIGHUP, &saved_->old_hup, nullptr);
  delete saved_;
}

int stop_signal() { return g_stop; }

std::string stop_signal_words(int sig) {
  if (sig == SIGINT) return "interrupted (SIGINT)";
  if (sig == SIGHUP) return "hung up (SIGHUP: the terminal or session closed)";
  return "terminated (SIGTERM)";
}

}  // namespace demcal::jobs
