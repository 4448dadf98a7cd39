#pragma once
// Thread counts with one meaning across previz (issue 34). An options struct's `threads` asks for
// that many threads; 0 (or less) means "all": OpenMP's default team (the cores, or
// OMP_NUM_THREADS where it is set, as under Slurm or `previz batch`). Never less than 1.
namespace previz {

// OpenMP's default team size (omp_get_max_threads()), at least 1.
int defaultThreadCount();

// `requested` when it is > 0, else defaultThreadCount().
int resolveThreads(int requested);

// The machine's cores (std::thread::hardware_concurrency()), at least 1; unlike
// defaultThreadCount() blind to OMP_NUM_THREADS: for dividing the whole machine among jobs
// and for benchmarks that name their figures by the machine's cores.
int coreCount();

}  // namespace previz
