// Shared part of the libFuzzer targets of the input parsers (tests/fuzz/fuzz_*.cpp).
//
// The parsers read files, so every input is written to a file in a private folder
// (under /dev/shm when it exists: memory, no disk traffic) and the parser reads it
// from there. A parser that rejects the input with an InputError behaves as it
// should; a crash, a sanitizer report, a hang, a huge allocation, another exception
// or a broken invariant of an accepted input (Require) is a finding.
#pragma once

#include <stdlib.h>
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include "common/errors.hpp"
#include "io/mesh_h5.hpp"

namespace softbody::fuzz {

// A folder of this process, removed (with everything in it) at exit.
class InputFolder {
 public:
  InputFolder() {
    std::error_code error;
    const bool shm =
        std::filesystem::is_directory("/dev/shm", error) && access("/dev/shm", W_OK) == 0;
    std::string pattern =
        ((shm ? std::filesystem::path("/dev/shm") : std::filesystem::temp_directory_path()) /
         "softbody-fuzz-XXXXXX")
            .string();
    if (!mkdtemp(pattern.data())) {
      std::perror("softbody fuzz: mkdtemp");
      std::abort();
    }
    path_ = pattern;
  }
  ~InputFolder() {
    std::error_code ignored;
    std::filesystem::remove_all(path_, ignored);
  }
  InputFolder(const InputFolder &) = delete;
  InputFolder &operator=(const InputFolder &) = delete;

  // <folder>/name.
  std::string Path(const std::string &name) const { return (path_ / name).string(); }

  // Writes `size` bytes to <folder>/name and returns its path.
  std::string Write(const std::string &name, const uint8_t *data, size_t size) const {
    const std::string path = Path(name);
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char *>(data), static_cast<std::streamsize>(size));
    out.close();
    if (!out) {
      std::fprintf(stderr, "softbody fuzz: cannot write %s\n", path.c_str());
      std::abort();
    }
    return path;
  }
  std::string Write(const std::string &name, const std::string &text) const {
    return Write(name, reinterpret_cast<const uint8_t *>(text.data()), text.size());
  }

 private:
  std::filesystem::path path_;
};

// The folder of this process (made on first use).
inline const InputFolder &Folder() {
  static const InputFolder folder;
  return folder;
}

// Small valid meshes next to the fuzzed scene and constraints files, by the names
// the seed scenes use: tet.mesh (1 tet), cube.mesh (8 vertices, 6 tets), tet.msh
// (gmsh 2.2, 1 tet), tet41.msh (gmsh 4.1, 1 tet) and tet.off (a tetrahedron's
// surface; the fuzz targets refuse to run TetGen on it, see fuzz_scene.cpp).
inline void WriteMeshes(const InputFolder &folder) {
  folder.Write("tet.mesh",
               "MeshVersionFormatted 2\nDimension 3\nVertices\n4\n0 0 0 0\n1 0 0 0\n0 1 0 0\n"
               "0 0 1 0\nTetrahedra\n1\n1 2 3 4 0\nEnd\n");
  folder.Write("cube.mesh",
               "MeshVersionFormatted 2\nDimension 3\nVertices\n8\n0 0 0 0\n1 0 0 0\n0 1 0 0\n"
               "1 1 0 0\n0 0 1 0\n1 0 1 0\n0 1 1 0\n1 1 1 0\nTetrahedra\n6\n1 2 4 8 0\n"
               "1 2 6 8 0\n1 3 4 8 0\n1 3 7 8 0\n1 5 6 8 0\n1 5 7 8 0\nEnd\n");
  folder.Write("tet.msh",
               "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n4\n1 0 0 0\n2 1 0 0\n3 0 1 0\n"
               "4 0 0 1\n$EndNodes\n$Elements\n1\n1 4 2 0 1 1 2 3 4\n$EndElements\n");
  folder.Write("tet41.msh",
               "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n1 4 1 4\n3 1 0 4\n1\n2\n3\n4\n"
               "0 0 0\n1 0 0\n0 1 0\n0 0 1\n$EndNodes\n$Elements\n1 1 1 1\n3 1 4 1\n"
               "1 1 2 3 4\n$EndElements\n");
  folder.Write("tet.off",
               "OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n"
               "3 0 3 2\n3 1 2 3\n");
  // The softbody HDF5 mesh file, read without MPI (the fuzzers do not initialise it).
  TetMesh tet;
  tet.vertices.resize(4, 3);
  tet.vertices << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1;
  tet.tets.resize(1, 4);
  tet.tets << 0, 1, 2, 3;
  WriteMeshH5(folder.Path("tet.h5"), tet, "fuzz");
}

// Runs `parse`; an InputError is a clean rejection of bad input.
template <class Parse>
void ParseOrReject(Parse parse) {
  try {
    parse();
  } catch (const InputError &) {}
}

// An invariant of an accepted input; aborts (a finding) when it does not hold.
inline void Require(bool holds, const char *what) {
  if (holds) return;
  std::fprintf(stderr, "softbody fuzz: accepted input breaks an invariant: %s\n", what);
  std::abort();
}

}  // namespace softbody::fuzz
