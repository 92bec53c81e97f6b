// Writes a DoubleGrid .vdb from a float64 .npy array (the Python binding of OpenVDB 10 has
// no DoubleGrid). Usage: make_double_vdb values.npy name background i0 j0 k0 voxel tx ty tz out.vdb
// Voxel (i0 + a, j0 + b, k0 + c) takes values[a][b][c] (C order) and is active unless it equals
// the background; the transform is uniform scale `voxel` followed by translation (tx, ty, tz).
#include <openvdb/openvdb.h>

#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iostream>
#include <string>
#include <vector>

int main(int argc, char** argv)
{
    if (argc != 12) {
        std::cerr << "usage: make_double_vdb values.npy name background i0 j0 k0 voxel tx ty tz out.vdb\n";
        return 2;
    }
    std::ifstream in(argv[1], std::ios::binary);
    char magic[8];
    in.read(magic, 8);
    if (!in || std::memcmp(magic, "\x93NUMPY\x01\x00", 8) != 0) {
        std::cerr << "expected a version 1.0 .npy file\n";
        return 1;
    }
    uint16_t headerLen = 0;
    in.read(reinterpret_cast<char*>(&headerLen), 2);
    std::string header(headerLen, ' ');
    in.read(&header[0], headerLen);
    if (header.find("'descr': '<f8'") == std::string::npos ||
        header.find("'fortran_order': False") == std::string::npos) {
        std::cerr << "expected little-endian float64 in C order: " << header << "\n";
        return 1;
    }
    const auto open = header.find("'shape': (");
    int dims[3] = {0, 0, 0};
    if (open == std::string::npos ||
        std::sscanf(header.c_str() + open, "'shape': (%d, %d, %d)", &dims[0], &dims[1], &dims[2]) != 3) {
        std::cerr << "expected a 3D shape: " << header << "\n";
        return 1;
    }
    std::vector<double> values(size_t(dims[0]) * dims[1] * dims[2]);
    in.read(reinterpret_cast<char*>(values.data()), std::streamsize(values.size() * sizeof(double)));
    if (!in) {
        std::cerr << "truncated .npy data\n";
        return 1;
    }

    openvdb::initialize();
    const double background = std::atof(argv[3]);
    auto grid = openvdb::DoubleGrid::create(background);
    grid->setName(argv[2]);
    const openvdb::Coord origin(std::atoi(argv[4]), std::atoi(argv[5]), std::atoi(argv[6]));
    auto acc = grid->getAccessor();
    size_t n = 0;
    for (int a = 0; a < dims[0]; ++a) {
        for (int b = 0; b < dims[1]; ++b) {
            for (int c = 0; c < dims[2]; ++c, ++n) {
                if (values[n] != background) {
                    acc.setValueOn(origin + openvdb::Coord(a, b, c), values[n]);
                }
            }
        }
    }
    auto xform = openvdb::math::Transform::createLinearTransform(std::atof(argv[7]));
    xform->postTranslate(openvdb::Vec3d(std::atof(argv[8]), std::atof(argv[9]), std::atof(argv[10])));
    grid->setTransform(xform);
    openvdb::io::File(argv[11]).write({grid});
    return 0;
}
