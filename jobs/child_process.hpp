#pragma once
// A child process bound to this one: the kernel sends it SIGKILL when this process
// dies (a kill -9 included), so no worker or gnuplot outlives the demcal that
// started it.
#include <sys/types.h>

namespace demcal::jobs {

// fork(): -1 on failure, the child's pid in the parent, 0 in the child. A child
// whose parent died before the binding took leaves at once with _exit(orphan_exit).
pid_t fork_bound_to_parent(int orphan_exit);

}  // namespace demcal::jobs
