#pragma once
// Temporaries an interrupted atomic write leaves beside its target (a kill -9, a power cut):
// writeFileAtomic's ".<file>.tmp.<pid>.<thread>.<n>" (core/io.h) and the point cloud writer's
// ".<file>.pcl.<pid>.<n>" (carving/pointcloud.cpp). No reader takes them for an output, but a
// resumed command should not leave them lying about (scripts/killtest.sh counts them).
#include <filesystem>

namespace previz {

// Removes such temporaries in 'dir' (and below it when 'recursive') whose process is gone; a
// live process's (another shard writing now, or this one) are left alone. Returns how many were
// removed; never throws (what cannot be read or removed is left).
int removeLeftoverTemporaries(const std::filesystem::path& dir, bool recursive);

}  // namespace previz
