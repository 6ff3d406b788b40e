// CPU seconds this process has used (user + system), for the modules' cost reports: on a
// machine shared with other runs, CPU time rather than wall time says where a run's work goes.
#pragma once

#include <ctime>

namespace granmpm {

inline double process_cpu_seconds() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

} // namespace granmpm
