// OpenVDB grids written by tests: the grids of renderer/grid_medium.h's tests and uploads of .vdb assets.
#pragma once

#include <filesystem>
#include <string>

#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>

namespace tessera::test {

constexpr float kVoxel = 0.05f;  // the test grids' voxel size, scene units

// A grid of voxel size kVoxel named `name` whose voxels of index -2 to n + 1 on each axis hold `value(i, j, k)`: the
// densities are those values through the box [0, (n - 1) kVoxel]^3 of voxel centres (interpolation reaches the
// background only beyond the voxels outside it).
template <typename F>
openvdb::FloatGrid::Ptr make_grid(int n, F value, const std::string& name = "density") {
  openvdb::initialize();
  auto grid = openvdb::FloatGrid::create(0.0f);
  grid->setTransform(openvdb::math::Transform::createLinearTransform(kVoxel));
  grid->setName(name);
  auto acc = grid->getAccessor();
  for (int i = -2; i <= n + 1; ++i)
    for (int j = -2; j <= n + 1; ++j)
      for (int k = -2; k <= n + 1; ++k) acc.setValue(openvdb::Coord(i, j, k), value(i, j, k));
  return grid;
}

// Writes `grids` to the .vdb file `path`.
inline void write_vdb(const std::filesystem::path& path, const openvdb::GridPtrVec& grids) {
  openvdb::initialize();
  openvdb::io::File file(path.string());
  file.write(grids);
  file.close();
}

}  // namespace tessera::test
