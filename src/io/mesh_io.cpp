#include "io/mesh_io.hpp"

#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <unordered_map>
#include <vector>

#include "common/errors.hpp"
#include "common/text_reader.hpp"
#include "fem/element.hpp"
#include "io/mesh_h5.hpp"

extern char **environ;

namespace softbody {

namespace fs = std::filesystem;

static bool EndsWith(const std::string &s, const std::string &suffix) {
  return s.size() >= suffix.size() &&
         s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

TetMesh ReadTetMesh(const std::string &path, const MeshingOptions &meshing) {
  if (EndsWith(path, ".mesh")) return ReadMedit(path);
  if (EndsWith(path, ".off")) return ReadOff(path, meshing);
  if (EndsWith(path, ".msh")) return ReadGmsh(path);
  if (EndsWith(path, ".h5")) return ReadMeshH5(path);
  throw InputError(Where(path, 0,
                         "unknown mesh format (expected a MEDIT .mesh, an OFF surface .off, a "
                         "gmsh .msh or a softbody mesh .h5 file)"));
}

namespace {

// ------------------------------------------------------------ shared checks

// Sections of MEDIT files that we skip: number of integers per row.
const std::map<std::string, int> kSkippedSections = {{"Edges", 3},
                                                     {"Triangles", 4},
                                                     {"Quadrilaterals", 5},
                                                     {"Hexahedra", 9},
                                                     {"Prisms", 7},
                                                     {"Corners", 1},
                                                     {"Ridges", 1},
                                                     {"RequiredVertices", 1},
                                                     {"RequiredEdges", 1},
                                                     {"RequiredTriangles", 1},
                                                     {"Normals", 3},
                                                     {"Tangents", 3},
                                                     {"NormalAtVertices", 2},
                                                     {"TangentAtEdges", 3}};

// A count read from `token` (of the current line). A row takes at least one byte,
// so a count beyond the bytes left is rejected before anything is allocated (a
// short section is reported where the file ends).
long ParseCount(const TextReader &in, std::string_view token, const char *what) {
  const long count = in.ParseInteger(token, (std::string("number of ") + what).c_str());
  if (count < 0) in.Fail(std::string("negative number of ") + what);
  if (static_cast<size_t>(count) > in.remaining_bytes())
    in.Fail(std::to_string(count) + " " + what +
            " announced, more than the rest of the file holds");
  return count;
}

// A section's row count, the next token.
long ExpectCount(TextReader &in, const char *section) {
  return ParseCount(in, in.ExpectToken((std::string("number of ") + section).c_str()), section);
}

// How many rows to allocate for `count` rows of at least `tokens_per_row` tokens:
// no more than the bytes left can hold (every token takes a character and a
// separator). A count that the file cannot hold then costs no more memory than
// the file itself, and the short section is still reported where the file ends.
// Readers store a row only after reading all its tokens, so row r is stored only
// when the bytes held r + 1 rows: within the rows allocated.
Eigen::Index RowsToAllocate(const TextReader &in, long count, size_t tokens_per_row) {
  const size_t fit = (in.remaining_bytes() + 1) / (2 * tokens_per_row);
  return static_cast<Eigen::Index>(std::min(static_cast<size_t>(count), fit));
}

// True when the tet on these four rows of `vertices` has |V| <= kDegenerateVolume L^3
// (the one degeneracy test of every reader).
bool IsDegenerate(const Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> &vertices,
                  const int32_t *corners) {
  TetPositions X;
  for (int a = 0; a < 4; ++a) X.row(a) = vertices.row(corners[a]);
  return IsDegenerateTet(X);
}

void CheckTet(const TetMesh &mesh, int32_t t, TextReader &in) {
  if (IsDegenerate(mesh.vertices, mesh.tets.row(t).data()))
    in.Fail("tetrahedron " + std::to_string(t + 1) + " is degenerate (zero volume)");
}

void SetTets(const std::vector<std::array<int32_t, 4>> &tets, TetMesh *mesh) {
  mesh->tets.resize(static_cast<Eigen::Index>(tets.size()), 4);
  for (size_t t = 0; t < tets.size(); ++t)
    for (int a = 0; a < 4; ++a) mesh->tets(t, a) = tets[t][a];
}

}  // namespace

// ------------------------------------------------------------------- MEDIT

namespace {

// After "Vertices": n, then n rows "x y z ref".
void ReadMeditVertices(TextReader &in, TetMesh *mesh) {
  const long n = ExpectCount(in, "vertices");
  mesh->vertices.resize(RowsToAllocate(in, n, 4), 3);  // rows "x y z ref"
  for (long v = 0; v < n; ++v) {
    Eigen::RowVector3d x;
    for (int c = 0; c < 3; ++c) x[c] = in.ExpectReal("vertex coordinate");
    in.ExpectInteger("vertex reference");
    mesh->vertices.row(v) = x;
  }
}

// After "Tetrahedra": n, then n rows "a b c d ref" (1-based), none degenerate.
void ReadMeditTets(TextReader &in, TetMesh *mesh) {
  const long n = ExpectCount(in, "tetrahedra");
  mesh->tets.resize(RowsToAllocate(in, n, 5), 4);  // rows "a b c d ref"
  for (long t = 0; t < n; ++t) {
    std::array<int32_t, 4> corners;
    for (int a = 0; a < 4; ++a) {
      const long index = in.ExpectInteger("tetrahedron vertex index");
      if (index < 1 || index > mesh->num_vertices())
        in.Fail("tetrahedron " + std::to_string(t + 1) + ": vertex index " + std::to_string(index) +
                " out of range 1.." + std::to_string(mesh->num_vertices()));
      corners[a] = static_cast<int32_t>(index - 1);
    }
    in.ExpectInteger("tetrahedron reference");
    for (int a = 0; a < 4; ++a) mesh->tets(t, a) = corners[a];
    CheckTet(*mesh, static_cast<int32_t>(t), in);
  }
}

// A section softbody does not use (kSkippedSections): its count and rows.
void SkipMeditSection(TextReader &in, std::string_view keyword) {
  const auto section = kSkippedSections.find(std::string(keyword));
  if (section == kSkippedSections.end())
    in.Fail("unknown MEDIT keyword '" + std::string(keyword) + "'");
  const long n = ExpectCount(in, section->first.c_str());
  for (long row = 0; row < n * section->second; ++row) in.ExpectToken(section->first.c_str());
}

}  // namespace

TetMesh ReadMedit(const std::string &path) {
  TextReader in(path);
  TetMesh mesh;
  bool have_vertices = false, have_tets = false;
  std::string_view keyword;
  while (in.NextToken(&keyword)) {
    if (keyword == "End") break;
    if (keyword == "MeshVersionFormatted") {
      in.ExpectInteger("mesh version");
    } else if (keyword == "Dimension") {
      if (in.ExpectInteger("dimension") != 3) in.Fail("only 3-dimensional meshes are supported");
    } else if (keyword == "Vertices") {
      if (have_vertices) in.Fail("second Vertices section");
      ReadMeditVertices(in, &mesh);
      have_vertices = true;
    } else if (keyword == "Tetrahedra") {
      if (!have_vertices) in.Fail("Tetrahedra before Vertices");
      if (have_tets) in.Fail("second Tetrahedra section");
      ReadMeditTets(in, &mesh);
      have_tets = true;
    } else {
      SkipMeditSection(in, keyword);
    }
  }
  if (!have_tets || mesh.num_tets() == 0) in.Fail("no tetrahedra in the mesh");
  return mesh;
}

// --------------------------------------------------------------------- OFF

namespace {

// The counts line "nv nf [ne]" after the header OFF (maybe on the header's line).
void ReadOffCounts(TextReader &in, long *nv, long *nf) {
  std::vector<std::string_view> fields;
  if (!in.NextLine(&fields)) in.Fail("empty file (expected the header OFF)");
  if (fields[0] != "OFF")
    in.Fail("expected the header 'OFF', found '" + std::string(fields[0]) + "'");
  fields.erase(fields.begin());  // the counts may follow on the header's line
  if (fields.empty() && !in.NextLine(&fields))
    in.Fail("expected the counts 'nv nf ne', found end of file");
  if (fields.size() != 2 && fields.size() != 3)
    in.Fail("expected the counts 'nv nf ne', found " + std::to_string(fields.size()) + " fields");
  *nv = ParseCount(in, fields[0], "vertices");
  *nf = ParseCount(in, fields[1], "faces");
  if (fields.size() == 3) in.ParseInteger(fields[2], "number of edges");
  if (*nv < 4 || *nf < 4)
    in.Fail("a closed surface needs at least 4 vertices and 4 faces (found " + std::to_string(*nv) +
            " and " + std::to_string(*nf) + ")");
}

// nv rows "x y z", no two at the same position.
void ReadOffVertices(TextReader &in, long nv, OffSurface *surface) {
  std::vector<std::string_view> fields;
  std::map<std::array<double, 3>, long> first_at;        // exact coordinates -> vertex
  surface->vertices.reserve(RowsToAllocate(in, nv, 3));  // rows "x y z"
  surface->vertex_lines.reserve(surface->vertices.capacity());
  for (long v = 0; v < nv; ++v) {
    if (!in.NextLine(&fields))
      in.Fail("expected " + std::to_string(nv) + " vertex rows, found " + std::to_string(v));
    if (fields.size() != 3)
      in.Fail("vertex " + std::to_string(v) + ": expected 3 coordinates 'x y z', found " +
              std::to_string(fields.size()) + " fields");
    Eigen::RowVector3d x;
    for (int c = 0; c < 3; ++c) x[c] = in.ParseReal(fields[c], "vertex coordinate");
    const auto [where, inserted] = first_at.insert({{x[0], x[1], x[2]}, v});
    if (!inserted)  // TetGen would merge the two and renumber the rest
      in.Fail("vertex " + std::to_string(v) + " repeats the position of vertex " +
              std::to_string(where->second) + " (line " +
              std::to_string(surface->vertex_lines[where->second]) + ")");
    surface->vertices.push_back(x);
    surface->vertex_lines.push_back(in.line());
  }
}

// Face f's row "k i1 ... ik": k >= 3 distinct vertex indices in 0 .. nv - 1.
std::vector<int32_t> ParseOffFace(TextReader &in, const std::vector<std::string_view> &fields,
                                  long f, long nv) {
  const long k = in.ParseInteger(fields[0], "number of face vertices");
  if (k < 3)
    in.Fail("face " + std::to_string(f) + " has " + std::to_string(k) +
            " vertices (at least 3 needed)");
  if (static_cast<long>(fields.size()) - 1 < k)
    in.Fail("face " + std::to_string(f) + ": " + std::to_string(k) + " vertex indices announced, " +
            std::to_string(fields.size() - 1) + " found");
  std::vector<int32_t> face(k);
  for (long i = 0; i < k; ++i) {  // fields after the k indices (a colour) are ignored
    const long index = in.ParseInteger(fields[1 + i], "face vertex index");
    if (index < 0 || index >= nv)
      in.Fail("face " + std::to_string(f) + ": vertex index " + std::to_string(index) +
              " out of range 0.." + std::to_string(nv - 1));
    face[i] = static_cast<int32_t>(index);
  }
  std::vector<int32_t> sorted = face;  // O(k log k): a face may have many vertices
  std::sort(sorted.begin(), sorted.end());
  const auto repeated = std::adjacent_find(sorted.begin(), sorted.end());
  if (repeated != sorted.end())
    in.Fail("face " + std::to_string(f) + " repeats vertex " + std::to_string(*repeated));
  return face;
}

// nf face rows, then nothing.
void ReadOffFaces(TextReader &in, long nv, long nf, OffSurface *surface) {
  std::vector<std::string_view> fields;
  surface->faces.reserve(RowsToAllocate(in, nf, 4));  // rows "k i1 ... ik", k >= 3
  for (long f = 0; f < nf; ++f) {
    if (!in.NextLine(&fields))
      in.Fail("expected " + std::to_string(nf) + " face rows, found " + std::to_string(f));
    surface->faces.push_back(ParseOffFace(in, fields, f, nv));
  }
  if (in.NextLine(&fields))
    in.Fail("unexpected content after the " + std::to_string(nf) + " faces");
}

}  // namespace

OffSurface ReadOffSurface(const std::string &path) {
  TextReader in(path);
  OffSurface surface;
  long nv, nf;
  ReadOffCounts(in, &nv, &nf);
  ReadOffVertices(in, nv, &surface);
  ReadOffFaces(in, nv, nf, &surface);
  return surface;
}

namespace {

// A folder of our own under the system's temporary folder, removed with everything
// in it when this object goes.
class TemporaryFolder {
 public:
  explicit TemporaryFolder(const std::string &owner) {
    std::error_code error;
    const fs::path parent = fs::temp_directory_path(error);  // $TMPDIR, else /tmp
    if (error)
      throw InputError(Where(owner, 0, "no temporary folder for TetGen: " + error.message()));
    std::string pattern = (parent / "softbody-tetgen-XXXXXX").string();
    if (!mkdtemp(pattern.data()))
      throw InputError(Where(owner, 0,
                             "cannot create a temporary folder for TetGen under " +
                                 parent.string() + ": " + std::strerror(errno)));
    path_ = pattern;
  }
  ~TemporaryFolder() {
    std::error_code ignored;
    fs::remove_all(path_, ignored);
  }
  TemporaryFolder(const TemporaryFolder &) = delete;
  TemporaryFolder &operator=(const TemporaryFolder &) = delete;
  const fs::path &path() const { return path_; }

 private:
  fs::path path_;
};

// TetGen's piecewise linear complex format: nodes, facets (one polygon each),
// no holes, no regions. Coordinates with 17 digits, so they come back bit for bit.
void WriteSmesh(const OffSurface &surface, const fs::path &smesh, const std::string &owner) {
  std::ofstream out(smesh);
  out.precision(17);
  out << "# surface of " << owner << "\n" << surface.vertices.size() << " 3 0 0\n";
  for (size_t v = 0; v < surface.vertices.size(); ++v)
    out << v << ' ' << surface.vertices[v][0] << ' ' << surface.vertices[v][1] << ' '
        << surface.vertices[v][2] << '\n';
  out << surface.faces.size() << " 0\n";
  for (const std::vector<int32_t> &face : surface.faces) {
    out << face.size();
    for (int32_t index : face) out << ' ' << index;
    out << '\n';
  }
  out << "0\n0\n";
  out.close();
  if (!out) throw InputError(Where(owner, 0, "cannot write TetGen's input file " + smesh.string()));
}

// Runs `tetgen switches input`, standard output and error into `log`, and
// returns its wait status. InputError naming `owner` when it cannot be started.
int RunTetgen(const std::string &switches, const fs::path &input, const fs::path &log,
              const std::string &owner) {
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, STDIN_FILENO, "/dev/null", O_RDONLY, 0);
  posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, log.c_str(),
                                   O_WRONLY | O_CREAT | O_TRUNC, 0600);
  posix_spawn_file_actions_adddup2(&actions, STDOUT_FILENO, STDERR_FILENO);
  std::string program = "tetgen", argument = "-" + switches, file = input.string();
  char *argv[] = {program.data(), argument.data(), file.data(), nullptr};
  pid_t pid;
  const int error = posix_spawnp(&pid, program.c_str(), &actions, nullptr, argv, environ);
  posix_spawn_file_actions_destroy(&actions);
  if (error == ENOENT)
    throw InputError(Where(owner, 0,
                           "cannot tetrahedralise the surface: the program 'tetgen' is not on PATH "
                           "(install TetGen, Debian package tetgen)"));
  if (error != 0)
    throw InputError(Where(owner, 0, std::string("cannot run 'tetgen': ") + std::strerror(error)));
  int status = 0;
  while (waitpid(pid, &status, 0) < 0) {
    if (errno != EINTR)
      throw InputError(
          Where(owner, 0, std::string("lost the 'tetgen' process: ") + std::strerror(errno)));
  }
  return status;
}

std::string DescribeStatus(int status) {
  if (WIFEXITED(status)) return "exit status " + std::to_string(WEXITSTATUS(status));
  if (WIFSIGNALED(status))
    return "killed by signal " + std::to_string(WTERMSIG(status)) + ", " +
           strsignal(WTERMSIG(status));
  return "wait status " + std::to_string(status);
}

std::string Trim(const std::string &line) {
  const size_t first = line.find_first_not_of(" \t\r");
  if (first == std::string::npos) return "";
  return line.substr(first, line.find_last_not_of(" \t\r") - first + 1);
}

// The last line of TetGen's log that says something: not blank, not its
// "Opening <file>." greeting, not the C++ runtime's "terminate called after
// throwing ..." (Debian's TetGen throws an int where it would print its reason).
std::string LastMeaningfulLine(const fs::path &log) {
  std::ifstream in(log);
  std::string line, last;
  while (std::getline(in, line)) {
    line = Trim(line);
    if (line.empty() || line.rfind("Opening ", 0) == 0 || line.rfind("terminate called", 0) == 0)
      continue;
    last = line;
  }
  return last;
}

// Runs `tetgen -pd`, which only looks for intersecting faces. Returns what it
// found, in OFF face numbers, or "" when it found nothing.
std::string FindSelfIntersections(const fs::path &smesh, const fs::path &folder,
                                  const std::string &owner) {
  const fs::path log = folder / "detect.log";
  const int status = RunTetgen("pd", smesh, log, owner);
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) return "";
  std::ifstream in(log);
  std::string line, example;
  long pairs = 0;
  while (std::getline(in, line)) {
    int a, b;  // this report numbers facets (our OFF faces) from 1
    if (example.empty() &&
        std::sscanf(Trim(line).c_str(), "Facet #%d intersects facet #%d", &a, &b) == 2)
      example = ", e.g. faces " + std::to_string(a - 1) + " and " + std::to_string(b - 1);
    const size_t found = line.find("Found ");
    if (found != std::string::npos && line.find("intersecting") != std::string::npos)
      pairs = std::atol(line.c_str() + found + 6);
  }
  if (pairs == 0) return "";
  return "the surface intersects itself (tetgen -d finds " + std::to_string(pairs) +
         " pairs of intersecting faces" + example + ")";
}

// TetGen's output .node file: "n 3 nattr nbnd", then rows "index x y z [attr...] [bnd]";
// the first row's index (0 or 1) is the numbering base of the .ele file too.
std::vector<Eigen::RowVector3d> ReadTetgenNodes(const fs::path &node_file, long *base) {
  TextReader in(node_file.string());
  const long n = ExpectCount(in, "points");
  if (in.ExpectInteger("dimension") != 3) in.Fail("not a 3-dimensional point list");
  const long attributes = in.ExpectInteger("number of point attributes");
  const long markers = in.ExpectInteger("number of boundary markers");
  if (attributes < 0 || markers < 0 || markers > 1) in.Fail("bad .node header");
  std::vector<Eigen::RowVector3d> points;
  points.reserve(RowsToAllocate(in, n, 4));  // rows "index x y z"
  for (long v = 0; v < n; ++v) {
    const long index = in.ExpectInteger("point index");
    if (v == 0) {
      if (index != 0 && index != 1) in.Fail("the first point's index must be 0 or 1");
      *base = index;
    }
    if (index != *base + v) in.Fail("point index " + std::to_string(index) + " out of sequence");
    Eigen::RowVector3d x;
    for (int c = 0; c < 3; ++c) x[c] = in.ExpectReal("point coordinate");
    points.push_back(x);
    for (long k = 0; k < attributes + markers; ++k) in.ExpectReal("point attribute or marker");
  }
  return points;
}

// TetGen's output .ele file: "nt 4 nattr", then rows "index a b c d [attr...]".
std::vector<std::array<int32_t, 4>> ReadTetgenElements(const fs::path &ele_file, long base,
                                                       long num_points) {
  TextReader in(ele_file.string());
  const long n = ExpectCount(in, "tetrahedra");
  const long corners = in.ExpectInteger("nodes per tetrahedron");
  if (corners != 4)
    in.Fail(std::to_string(corners) + "-node tetrahedra: only 4-node ones are supported");
  const long attributes = in.ExpectInteger("number of tetrahedron attributes");
  if (attributes < 0) in.Fail("negative number of tetrahedron attributes");
  std::vector<std::array<int32_t, 4>> tets;
  tets.reserve(RowsToAllocate(in, n, 5));  // rows "index a b c d"
  for (long t = 0; t < n; ++t) {
    in.ExpectInteger("tetrahedron index");
    std::array<int32_t, 4> corners;
    for (int a = 0; a < 4; ++a) {
      const long index = in.ExpectInteger("tetrahedron corner") - base;
      if (index < 0 || index >= num_points) in.Fail("tetrahedron corner out of range");
      corners[a] = static_cast<int32_t>(index);
    }
    tets.push_back(corners);
    for (long k = 0; k < attributes; ++k) in.ExpectReal("tetrahedron attribute");
  }
  return tets;
}

std::string FormatReal(double value) {
  char text[32];
  std::snprintf(text, sizeof(text), "%.17g", value);
  return text;
}

}  // namespace

std::string CheckTetgenSwitches(const std::string &switches) {
  static const std::string kUsable = "pYqAaOSTXMczfenvgkJBFC";
  static const std::map<char, std::string> kRefused = {
      {'Q', "softbody adds Q itself"},
      {'V', "softbody runs TetGen quietly (Q) and reports its errors"},
      {'h', "only prints TetGen's help"},
      {'r', "needs a previous mesh"},
      {'i', "needs a file of extra points"},
      {'m', "needs a sizing-function file"},
      {'w', "needs point weights"},
      {'N', "suppresses the .node file softbody reads"},
      {'E', "suppresses the .ele file softbody reads"},
      {'I', "renames the output files softbody reads"},
      {'R', "coarsening may remove surface vertices"},
      {'d', "only detects self-intersections, it makes no mesh"}};
  if (switches.empty() || !std::isalpha(static_cast<unsigned char>(switches[0])))
    return "'" + switches + "' must start with a switch letter (without '-'), e.g. pq1.414";
  if (switches.find('p') == std::string::npos)
    return "'" + switches + "' lacks p (tetrahedralise the surface)";
  for (const char c : switches) {
    if (std::isdigit(static_cast<unsigned char>(c)) || c == '.' || c == '/' || c == '-' || c == '+')
      continue;
    const auto refused = kRefused.find(c);
    if (refused != kRefused.end())
      return std::string("'") + c + "' is not allowed: " + refused->second;
    if (kUsable.find(c) == std::string::npos)
      return std::string("'") + c +
             "' is not a TetGen switch softbody can use (usable: " + kUsable +
             " and their numbers)";
  }
  return "";
}

namespace {

// TetGen writes coordinates with 17 digits, so the surface vertices come back
// bit for bit; this relative tolerance (of the surface's extent) only guards
// against a TetGen that writes fewer digits.
constexpr double kTetgenCoordinateTolerance = 1e-14;

// One TetGen run on an OFF surface: its input, switches and what failure says.
struct TetgenRun {
  std::string path;  // the OFF file, named in every message
  fs::path folder, smesh;
  std::string switches;  // as passed, without '-'

  // Throws the InputError of a failed run, with the self-intersections that
  // `tetgen -d` finds, if any (the usual cause).
  [[noreturn]] void Fail(const std::string &what) const {
    const std::string intersections = FindSelfIntersections(smesh, folder, path);
    throw InputError(Where(path, 0,
                           "TetGen (tetgen -" + switches + ") " + what +
                               (intersections.empty() ? "" : ": " + intersections)));
  }
};

// tetgen -<switches>[a<volume>]JQ: J keeps unused input points (so the
// numbering of the surface vertices survives), Q keeps the log to errors.
std::string TetgenSwitches(const MeshingOptions &meshing) {
  std::string switches = meshing.tetgen_switches;
  if (meshing.max_volume > 0) switches += "a" + FormatReal(meshing.max_volume);
  return switches + "JQ";
}

// TetGen's output: surface.1.node and surface.1.ele (none when there are no tets).
void ReadTetgenOutput(const TetgenRun &run, std::vector<Eigen::RowVector3d> *points,
                      std::vector<std::array<int32_t, 4>> *tets) {
  const fs::path node_file = run.folder / "surface.1.node";
  const fs::path ele_file = run.folder / "surface.1.ele";
  try {
    long base = 0;
    *points = ReadTetgenNodes(node_file, &base);
    if (fs::exists(ele_file))
      *tets = ReadTetgenElements(ele_file, base, static_cast<long>(points->size()));
  } catch (const InputError &error) {
    throw InputError(Where(run.path, 0, std::string("unreadable TetGen output: ") + error.what()));
  }
  if (tets->empty()) run.Fail("made no tetrahedra: the surface encloses no volume (is it open?)");
}

// The promise of the header: OFF vertex i is output point i (set to the OFF
// coordinates exactly), and every surface vertex belongs to a tet.
void KeepSurfaceNumbering(const TetgenRun &run, const OffSurface &surface,
                          const std::vector<std::array<int32_t, 4>> &tets,
                          std::vector<Eigen::RowVector3d> *points) {
  const long nv = static_cast<long>(surface.vertices.size());
  double extent = 0;
  for (const Eigen::RowVector3d &x : surface.vertices)
    extent = std::max(extent, x.cwiseAbs().maxCoeff());
  for (long v = 0; v < nv; ++v) {
    if (v >= static_cast<long>(points->size()) ||
        !(((*points)[v] - surface.vertices[v]).cwiseAbs().maxCoeff() <=
          kTetgenCoordinateTolerance * extent))
      throw InputError(Where(run.path, surface.vertex_lines[v],
                             "TetGen did not keep vertex " + std::to_string(v) +
                                 " in its place in the numbering (unsupported TetGen version?)"));
    (*points)[v] = surface.vertices[v];
  }
  std::vector<bool> used(points->size(), false);
  for (const auto &tet : tets)
    for (int32_t index : tet) used[index] = true;
  for (const std::vector<int32_t> &face : surface.faces)
    for (int32_t v : face)
      if (!used[v])
        run.Fail("left surface vertex " + std::to_string(v) + " (line " +
                 std::to_string(surface.vertex_lines[v]) +
                 ") out of every tetrahedron: the surface around it encloses no volume (is it "
                 "open?)");
}

// The mesh of TetGen's points and tets; none of its tets may be degenerate.
TetMesh TetgenMesh(const std::string &path, const std::vector<Eigen::RowVector3d> &points,
                   const std::vector<std::array<int32_t, 4>> &tets) {
  TetMesh mesh;
  mesh.vertices.resize(static_cast<Eigen::Index>(points.size()), 3);
  for (size_t v = 0; v < points.size(); ++v) mesh.vertices.row(v) = points[v];
  SetTets(tets, &mesh);
  for (int32_t t = 0; t < mesh.num_tets(); ++t)
    if (IsDegenerate(mesh.vertices, mesh.tets.row(t).data()))
      throw InputError(Where(path, 0,
                             "TetGen made a degenerate tetrahedron (" + std::to_string(t + 1) +
                                 " of " + std::to_string(mesh.num_tets()) + ")"));
  return mesh;
}

}  // namespace

TetMesh ReadOff(const std::string &path, const MeshingOptions &meshing) {
  const OffSurface surface = ReadOffSurface(path);
  const std::string bad_switches = CheckTetgenSwitches(meshing.tetgen_switches);
  if (!bad_switches.empty()) throw InputError(Where(path, 0, "TetGen switches " + bad_switches));
  if (!(meshing.max_volume >= 0 && std::isfinite(meshing.max_volume)))
    throw InputError(Where(path, 0, "the tetrahedron volume bound must be >= 0 and finite"));

  // The surface as a .smesh file in a folder of our own, meshed by TetGen.
  const TemporaryFolder folder(path);
  const TetgenRun run{path, folder.path(), folder.path() / "surface.smesh",
                      TetgenSwitches(meshing)};
  WriteSmesh(surface, run.smesh, path);
  const fs::path log = folder.path() / "tetgen.log";
  const int status = RunTetgen(run.switches, run.smesh, log, path);
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) {
    const std::string reason = LastMeaningfulLine(log);
    run.Fail("failed (" + DescribeStatus(status) + ")" +
             (reason.empty() ? "" : ", saying '" + reason + "'"));
  }

  std::vector<Eigen::RowVector3d> points;
  std::vector<std::array<int32_t, 4>> tets;
  ReadTetgenOutput(run, &points, &tets);
  KeepSurfaceNumbering(run, surface, tets, &points);
  return TetgenMesh(path, points, tets);
}

// -------------------------------------------------------------------- gmsh

namespace {

// Nodes per element of each gmsh element type (gmsh reference manual, "MSH file
// format"); 0 where the type is unknown.
int GmshNodesPerElement(long type) {
  static const int kNodes[] = {0, 2,  3,  4,  4, 8,  6,  5,  3,  6,  9, 10, 27, 18, 14, 1,
                               8, 20, 15, 13, 9, 10, 12, 15, 15, 21, 4, 5,  6,  20, 35, 56};
  if (type >= 1 && type < static_cast<long>(sizeof(kNodes) / sizeof(kNodes[0])))
    return kNodes[type];
  constexpr long kCubicHexahedron = 92, kQuarticHexahedron = 93;  // 64 and 125 nodes
  if (type == kCubicHexahedron) return 64;
  if (type == kQuarticHexahedron) return 125;
  return 0;
}

constexpr long kGmshTetrahedron = 4;

// What the sections read so far hold.
struct GmshMesh {
  TetMesh mesh;                                    // vertices: every node, in file order
  int32_t num_nodes = 0;                           // rows of mesh.vertices filled
  std::unordered_map<long, int32_t> index_of_tag;  // node tag -> row
  std::vector<std::array<int32_t, 4>> tets;
  bool have_nodes = false, have_elements = false;
};

void ExpectKeyword(TextReader &in, const char *keyword) {
  const std::string_view token = in.ExpectToken(keyword);
  if (token != keyword)
    in.Fail(std::string("expected ") + keyword + ", found '" + std::string(token) + "'");
}

// The next node's tag; returns its row.
int32_t AddNode(TextReader &in, GmshMesh *gmsh) {
  const long tag = in.ExpectInteger("node tag");
  if (tag < 1) in.Fail("node tag " + std::to_string(tag) + " (tags start at 1)");
  const auto [where, inserted] = gmsh->index_of_tag.insert({tag, gmsh->num_nodes});
  if (!inserted) in.Fail("node tag " + std::to_string(tag) + " appears twice");
  return gmsh->num_nodes++;
}

// Reads "x y z" into `row` (stored once all three are read; see RowsToAllocate).
void ReadPoint(TextReader &in, int32_t row, TetMesh *mesh) {
  Eigen::RowVector3d x;
  for (int c = 0; c < 3; ++c) x[c] = in.ExpectReal("node coordinate");
  mesh->vertices.row(row) = x;
}

// The node tags of one element of `type` whose tag has been read; kept when it
// is a tetrahedron.
void ReadElementNodes(TextReader &in, long tag, long type, GmshMesh *gmsh) {
  const int nodes = GmshNodesPerElement(type);
  if (nodes == 0)
    in.Fail("element " + std::to_string(tag) + ": unknown element type " + std::to_string(type));
  std::array<int32_t, 4> tet;
  for (int a = 0; a < nodes; ++a) {
    const long node = in.ExpectInteger("element node tag");
    if (type != kGmshTetrahedron) continue;
    const auto found = gmsh->index_of_tag.find(node);
    if (found == gmsh->index_of_tag.end())
      in.Fail("element " + std::to_string(tag) + ": node tag " + std::to_string(node) + " unknown");
    tet[a] = found->second;
  }
  if (type != kGmshTetrahedron) return;
  if (IsDegenerate(gmsh->mesh.vertices, tet.data()))
    in.Fail("element " + std::to_string(tag) + " (tetrahedron) is degenerate (zero volume)");
  gmsh->tets.push_back(tet);
}

// MSH 2: "n", then n rows "tag x y z".
void ReadNodes2(TextReader &in, GmshMesh *gmsh) {
  const long n = ExpectCount(in, "nodes");
  gmsh->mesh.vertices.resize(RowsToAllocate(in, n, 4), 3);  // rows "tag x y z"
  for (long v = 0; v < n; ++v) ReadPoint(in, AddNode(in, gmsh), &gmsh->mesh);
}

// MSH 2: "n", then n rows "tag type ntags tag... node...".
void ReadElements2(TextReader &in, GmshMesh *gmsh) {
  const long n = ExpectCount(in, "elements");
  for (long e = 0; e < n; ++e) {
    const long tag = in.ExpectInteger("element tag");
    const long type = in.ExpectInteger("element type");
    const long tags = ExpectCount(in, "element tags");
    for (long k = 0; k < tags; ++k) in.ExpectInteger("element tag");
    ReadElementNodes(in, tag, type, gmsh);
  }
}

// MSH 4.1: "blocks n min max", then per block "dim entity parametric m", m node
// tags, m rows "x y z [u [v [w]]]" (dim parametric coordinates when parametric).
void ReadNodes4(TextReader &in, GmshMesh *gmsh) {
  const long blocks = ExpectCount(in, "node blocks");
  const long n = ExpectCount(in, "nodes");
  in.ExpectInteger("smallest node tag");
  in.ExpectInteger("largest node tag");
  gmsh->mesh.vertices.resize(RowsToAllocate(in, n, 4), 3);  // a tag and "x y z" per node
  for (long b = 0; b < blocks; ++b) {
    const long dim = in.ExpectInteger("entity dimension");
    if (dim < 0 || dim > 3) in.Fail("entity dimension " + std::to_string(dim) + " not in 0..3");
    in.ExpectInteger("entity tag");
    const long parametric = in.ExpectInteger("parametric flag");
    if (parametric != 0 && parametric != 1) in.Fail("parametric flag must be 0 or 1");
    const long m = ExpectCount(in, "nodes in the block");
    if (gmsh->num_nodes + m > n)
      in.Fail("the node blocks hold more than the " + std::to_string(n) + " nodes announced");
    const int32_t first = gmsh->num_nodes;
    for (long v = 0; v < m; ++v) AddNode(in, gmsh);
    for (long v = 0; v < m; ++v) {
      ReadPoint(in, static_cast<int32_t>(first + v), &gmsh->mesh);
      for (long k = 0; k < parametric * dim; ++k) in.ExpectReal("parametric coordinate");
    }
  }
  if (gmsh->num_nodes != n)
    in.Fail(std::to_string(n) + " nodes announced, " + std::to_string(gmsh->num_nodes) +
            " in the blocks");
}

// MSH 4.1: "blocks n min max", then per block "dim entity type m" and m rows
// "tag node...".
void ReadElements4(TextReader &in, GmshMesh *gmsh) {
  const long blocks = ExpectCount(in, "element blocks");
  const long n = ExpectCount(in, "elements");
  in.ExpectInteger("smallest element tag");
  in.ExpectInteger("largest element tag");
  long total = 0;
  for (long b = 0; b < blocks; ++b) {
    in.ExpectInteger("entity dimension");
    in.ExpectInteger("entity tag");
    const long type = in.ExpectInteger("element type");
    const long m = ExpectCount(in, "elements in the block");
    total += m;
    if (total > n)
      in.Fail("the element blocks hold more than the " + std::to_string(n) + " elements announced");
    for (long e = 0; e < m; ++e) ReadElementNodes(in, in.ExpectInteger("element tag"), type, gmsh);
  }
  if (total != n)
    in.Fail(std::to_string(n) + " elements announced, " + std::to_string(total) + " in the blocks");
}

}  // namespace

TetMesh ReadGmsh(const std::string &path) {
  TextReader in(path);
  std::string_view token;
  if (!in.NextToken(&token) || token != "$MeshFormat")
    in.Fail("expected $MeshFormat at the start of a gmsh .msh file");
  const std::string version(in.ExpectToken("MSH version"));
  const bool version2 = version == "2" || version == "2.0" || version == "2.1" || version == "2.2";
  if (!version2 && version != "4.1")
    in.Fail("MSH version " + version + " is not supported (2.2 or 4.1)");
  const long file_type = in.ExpectInteger("file type");
  if (file_type != 0)
    in.Fail("binary .msh file: only ASCII is supported (save it from gmsh with Mesh.Binary = 0)");
  in.ExpectInteger("data size");
  ExpectKeyword(in, "$EndMeshFormat");

  GmshMesh gmsh;
  while (in.NextToken(&token)) {
    if (token == "$Nodes") {
      if (gmsh.have_nodes) in.Fail("second $Nodes section");
      version2 ? ReadNodes2(in, &gmsh) : ReadNodes4(in, &gmsh);
      ExpectKeyword(in, "$EndNodes");
      gmsh.have_nodes = true;
    } else if (token == "$Elements") {
      if (!gmsh.have_nodes) in.Fail("$Elements before $Nodes");
      if (gmsh.have_elements) in.Fail("second $Elements section");
      version2 ? ReadElements2(in, &gmsh) : ReadElements4(in, &gmsh);
      ExpectKeyword(in, "$EndElements");
      gmsh.have_elements = true;
    } else if (token.size() > 1 && token[0] == '$' && token.rfind("$End", 0) != 0) {
      const std::string section(token.substr(1)), end = "$End" + section;
      const long line = in.line();
      do {  // $PhysicalNames, $Entities, $Periodic, ...: skipped
        if (!in.NextToken(&token))
          throw InputError(Where(path, line, "section $" + section + " has no " + end));
      } while (token != end);
    } else {
      in.Fail("unexpected '" + std::string(token) + "' outside a section");
    }
  }
  if (gmsh.tets.empty()) in.Fail("no tetrahedra (element type 4) in the mesh");
  SetTets(gmsh.tets, &gmsh.mesh);
  return gmsh.mesh;
}

}  // namespace softbody
