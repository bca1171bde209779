#include "child_process.hpp"

#include <csignal>
#include <sys/prctl.h>
#include <unistd.h>

namespace demcal::jobs {

pid_t fork_bound_to_parent(int orphan_exit) {
  const pid_t parent = getpid();
  const pid_t pid = fork();
  if (pid == 0) {
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (getppid() != parent) _exit(orphan_exit);  // the parent died before prctl
  }
  return pid;
}

}  // namespace demcal::jobs
