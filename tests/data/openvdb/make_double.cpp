// Writes a DoubleGrid fixture for hytrace's OpenVDB reader (pyopenvdb 10 has no DoubleGrid).
//
// Usage: make_double SOURCE.npy OUT.vdb I J K BACKGROUND VOXEL_SIZE
// SOURCE.npy: a C-ordered little-endian float64 array of shape (nx, ny, nz); element
// [x][y][z] becomes voxel (I + x, J + y, K + z). Voxels equal to BACKGROUND stay inactive;
// the tree is then pruned (tolerance 0), so constant 8^3 blocks become tiles.
// Build: g++ -std=c++17 -O1 make_double.cpp -o make_double -lopenvdb -ltbb -lImath-3_1

#include <openvdb/openvdb.h>

#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

int main(int argc, char** argv)
{
    if (argc != 8) {
        std::cerr << "usage: make_double SOURCE.npy OUT.vdb I J K BACKGROUND VOXEL_SIZE\n";
        return 2;
    }
    std::ifstream in(argv[1], std::ios::binary);
    char magic[8];
    in.read(magic, 8);
    if (!in || std::memcmp(magic, "\x93NUMPY\x01\x00", 8) != 0) {
        std::cerr << "not a version 1.0 .npy file\n";
        return 1;
    }
    uint16_t headerLen = 0;
    in.read(reinterpret_cast<char*>(&headerLen), 2);
    std::string header(headerLen, '\0');
    in.read(&header[0], headerLen);
    if (header.find("'descr': '<f8'") == std::string::npos
        || header.find("'fortran_order': False") == std::string::npos) {
        std::cerr << "expected a C-ordered <f8 array, got " << header << "\n";
        return 1;
    }
    const auto open = header.find('(', header.find("'shape'"));
    const auto close = header.find(')', open);
    std::stringstream shapeText(header.substr(open + 1, close - open - 1));
    long dims[3];
    char comma;
    shapeText >> dims[0] >> comma >> dims[1] >> comma >> dims[2];
    std::vector<double> values(size_t(dims[0] * dims[1] * dims[2]));
    in.read(reinterpret_cast<char*>(values.data()), std::streamsize(values.size() * 8));
    if (!in) {
        std::cerr << "short .npy file\n";
        return 1;
    }

    openvdb::initialize();
    const int i0 = std::atoi(argv[3]), j0 = std::atoi(argv[4]), k0 = std::atoi(argv[5]);
    const double background = std::atof(argv[6]);
    auto grid = openvdb::DoubleGrid::create(background);
    auto acc = grid->getAccessor();
    size_t n = 0;
    for (long x = 0; x < dims[0]; ++x) {
        for (long y = 0; y < dims[1]; ++y) {
            for (long z = 0; z < dims[2]; ++z, ++n) {
                if (values[n] != background) {
                    acc.setValue(openvdb::Coord(i0 + x, j0 + y, k0 + z), values[n]);
                }
            }
        }
    }
    grid->tree().prune();
    grid->setName("double_density");
    grid->setTransform(openvdb::math::Transform::createLinearTransform(std::atof(argv[7])));
    openvdb::io::File(argv[2]).write({grid});
    return 0;
}
