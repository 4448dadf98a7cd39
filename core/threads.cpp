// Thread counts (see threads.h).
#include "core/threads.h"

#include <omp.h>

#include <algorithm>
#include <thread>

namespace previz {

int defaultThreadCount() { return std::max(1, omp_get_max_threads()); }

int resolveThreads(int requested) { return requested > 0 ? requested : defaultThreadCount(); }

int coreCount() { return static_cast<int>(std::max(1u, std::thread::hardware_concurrency())); }

}  // namespace previz
