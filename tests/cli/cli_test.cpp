// The `vmap` program as a user runs it: every case starts the built binary, and checks
// its exit code, its message and its JSON. Options given on the command line and in a
// --config file must give the same JSON; every documented error exits with its documented
// code (0 ok, 1 bad input or failed run, 2 usage) and never aborts (134).

#include "support/shared_data.hpp"

#include <doctest/doctest.h>
#include <nlohmann/json.hpp>

#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <sstream>
#include <string>
#include <vector>

namespace fs = std::filesystem;

namespace {

struct Run {
  int code = -1;
  std::string out, err;
};

std::string quote(const std::string& s) {
  std::string q = "'";
  for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

std::string slurp(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

fs::path work_dir() {
  static const fs::path dir = [] {
    // One folder per process: CTest runs the self-contained and the data suite of this
    // executable at the same time, and each starts by emptying its folder.
    fs::path d = fs::path(VMAP_TEST_BINARY_DIR) / ("cli_work-" + std::to_string(::getpid()));
    fs::remove_all(d);
    fs::create_directories(d);
    return d;
  }();
  return dir;
}

/// Runs `vmap ARGS...` from the repository's root (the docs' working folder).
Run run_vmap(const std::vector<std::string>& args) {
  const fs::path out = work_dir() / "stdout.txt", err = work_dir() / "stderr.txt";
  std::string cmd = "cd " + quote(VMAP_TEST_SOURCE_DIR) + " && " + quote(VMAP_CLI_BINARY);
  for (const auto& a : args) cmd += " " + quote(a);
  cmd += " >" + quote(out.string()) + " 2>" + quote(err.string()) + " </dev/null";
  const int status = std::system(cmd.c_str());
  Run r;
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  r.out = slurp(out);
  r.err = slurp(err);
  return r;
}

const std::string sample = "examples/data/tum_fr1_rpy_60/rgb.txt";
const std::string frame_a = "examples/data/tum_fr1_rpy_60/rgb/1305031229.528748.jpg";
const std::string frame_b = "examples/data/tum_fr1_rpy_60/rgb/1305031229.564425.jpg";

/// The JSON without the fields that measure time.
nlohmann::json without_times(nlohmann::json j) {
  for (auto it = j.begin(); it != j.end();) {
    const std::string k = it.key();
    if (k == "seconds" || k == "fps" || (k.size() > 8 && k.substr(k.size() - 8) == "_seconds"))
      it = j.erase(it);
    else
      ++it;
  }
  return j;
}

void write(const fs::path& p, const std::string& text) {
  std::ofstream f(p, std::ios::binary);
  f << text;
}

/// The same run from the command line and from a config file: identical JSON.
void same_json(const std::vector<std::string>& fixed, const std::vector<std::string>& cli, const std::string& yaml,
               const std::string& name) {
  std::vector<std::string> a = fixed;
  a.insert(a.end(), cli.begin(), cli.end());
  const Run r1 = run_vmap(a);
  INFO("command line: " << r1.err);
  REQUIRE(r1.code == 0);
  const fs::path cfg = work_dir() / (name + ".yaml");
  write(cfg, yaml);
  std::vector<std::string> b = fixed;
  b.push_back("--config");
  b.push_back(cfg.string());
  const Run r2 = run_vmap(b);
  INFO("config: " << r2.err);
  REQUIRE(r2.code == 0);
  const auto j1 = without_times(nlohmann::json::parse(r1.out));
  const auto j2 = without_times(nlohmann::json::parse(r2.out));
  CHECK(j1 == j2);
  CHECK(j1.contains("options"));
}

void usage_error(const std::vector<std::string>& args, const std::string& message) {
  const Run r = run_vmap(args);
  INFO("stderr: " << r.err);
  CHECK(r.code == 2);
  CHECK(r.err.find(message) != std::string::npos);
}

}  // namespace

TEST_CASE("cli: unknown subcommand is named with the closest match") {
  const Run r = run_vmap({"bild"});
  CHECK(r.code == 2);
  CHECK(r.err.find("unknown subcommand 'bild'; did you mean 'build'?") != std::string::npos);
  const Run none = run_vmap({"xyzzyq"});
  CHECK(none.code == 2);
  CHECK(none.err.find("unknown subcommand 'xyzzyq'; choose one of:") != std::string::npos);
  const Run nothing = run_vmap({});
  CHECK(nothing.code == 2);
}

TEST_CASE("cli: --help and --version exit 0 and document the exit codes") {
  const Run h = run_vmap({"--help"});
  CHECK(h.code == 0);
  CHECK(h.out.find("Exit codes: 0 ok; 1 bad input") != std::string::npos);
  const Run hb = run_vmap({"build", "--help"});
  CHECK(hb.code == 0);
  CHECK(hb.out.find("Exit codes") != std::string::npos);
  CHECK(run_vmap({"--version"}).code == 0);
}

TEST_CASE("cli: numeric options are refused with the option's name") {
  usage_error({"build", sample, "--start", "-1"}, "--start: must be >= 0, got '-1'");
  usage_error({"build", sample, "--stride", "18446744073709551615"}, "--stride: must be <= 1000000000");
  usage_error({"build", sample, "--stride", "0"}, "--stride: must be >= 1");
  usage_error({"build", sample, "--nfeatures", "1000000000"}, "--nfeatures: must be <= 100000");
  usage_error({"match", frame_a, frame_b, "--nfeatures", "2000000000"}, "--nfeatures: must be <= 100000");
  usage_error({"loops", sample, "--gt", sample, "--nfeatures", "2000000000"}, "--nfeatures: must be <= 100000");
  usage_error({"build", sample, "--threshold", "nan"}, "--threshold: must be a finite number");
  usage_error({"build", sample, "--tau", "1.5"}, "--threshold: must be in (0, 1]");
  usage_error({"sweep", sample, "--thresholds", "0.2,inf"}, "--thresholds: must be a finite number");
  usage_error({"localize", "--room", "--pan", "nan"}, "--pan: must be a finite number");
  usage_error({"localize", "--room", "--margin", "-1"}, "--margin: must be in (0, 2.99]");
  usage_error({"localize", "--room", "--neurons", "-5"}, "--neurons: must be >= 3");
  usage_error({"localize", "--room", "--neurons", "100000", "--lambda", "1"}, "--neurons: must be <= 5000");
  usage_error({"build", sample, "--start", "10", "--end", "5"}, "--end: must be > --start");
  usage_error({"build", sample, "--features", "surf"}, "--features: unknown descriptor 'surf'");
  usage_error({"build", sample, "--features", "xfeat"}, "--features xfeat needs --model");
  usage_error({"build", sample, "--estimator", "foo"}, "--estimator: unknown method 'foo'");
  usage_error({"build", sample, "--no-such-option"}, "no-such-option");
}

TEST_CASE("cli: conflicting options are usage errors") {
  usage_error({"localize", "--train", "x", "--poses", "y", "--every-other", "--query", "/nonexistent"},
              "--every-other and --query/--query-poses conflict");
  usage_error({"localize", "--room", "--train", "/nonexistent"}, "--room and --train conflict");
  usage_error({"localize"}, "give --room or --train");
  usage_error({"loops", sample, "--gt", "a", "--gt-poses", "b"}, "give at most one of --gt MATRIX and --gt-poses");
  usage_error({"loops", sample, "--gt", "a", "--labels", "x", "--detector", "yolox", "--model", "m"},
              "give --labels or --detector, not both");
  usage_error({"loops", sample, "--gt", "a", "--detector", "yolox"}, "--detector yolox needs --model PATH");
  usage_error({"detect", frame_a, "--sequence", sample, "--model", "m"}, "give either images or --sequence");
}

TEST_CASE("cli: outputs that are inputs are refused before any work, inputs unchanged") {
  const fs::path dir = work_dir() / "out_is_input";
  fs::create_directories(dir / "frames");
  fs::copy_file(fs::path(VMAP_TEST_SOURCE_DIR) / frame_a, dir / "frames" / "a.jpg");
  fs::copy_file(fs::path(VMAP_TEST_SOURCE_DIR) / frame_b, dir / "frames" / "b.jpg");
  const std::string frames = (dir / "frames").string();
  usage_error({"build", frames, "--out", frames}, "is also an input");
  usage_error({"build", frames, "--out", frames + "/maps"}, "is inside the input folder");
  CHECK(!fs::exists(dir / "frames" / "maps"));
  CHECK(std::distance(fs::directory_iterator(dir / "frames"), fs::directory_iterator{}) == 2);
  // detect IMG --out IMG: the image is not a folder to write into, and stays as it was.
  const std::string img = (dir / "frames" / "a.jpg").string();
  const std::string before = slurp(img);
  usage_error({"detect", img, "--model", img, "--out", img}, "is also an input");
  CHECK(slurp(img) == before);
  // loops --gt gt.txt --out DIR where DIR/pr.csv is the ground truth.
  fs::create_directories(dir / "gt");
  write(dir / "gt" / "pr.csv", "0\n");
  usage_error({"loops", sample, "--gt", (dir / "gt" / "pr.csv").string(), "--index", "all", "--out",
               (dir / "gt").string()},
              "is also an input");
  CHECK(slurp(dir / "gt" / "pr.csv") == "0\n");
}

TEST_CASE("cli: a symbolic link as an output file is refused") {
  const fs::path dir = work_dir() / "symlink_out";
  fs::create_directories(dir / "out");
  write(dir / "target.csv", "keep\n");
  fs::create_symlink(dir / "target.csv", dir / "out" / "pr.csv");
  usage_error({"loops", sample, "--gt", (dir / "target.csv").string(), "--index", "all", "--out",
               (dir / "out").string()},
              "is a symbolic link");
  CHECK(slurp(dir / "target.csv") == "keep\n");
  // The same for sweep's table, refused before any frame is read.
  fs::create_symlink(dir / "target.csv", dir / "out" / "sweep.csv");
  usage_error({"sweep", sample, "--out", (dir / "out").string()}, "is a symbolic link");
  CHECK(slurp(dir / "target.csv") == "keep\n");
}

TEST_CASE("cli: --out naming an existing file fails before the work; a missing folder is created") {
  const fs::path dir = work_dir() / "out_file";
  fs::create_directories(dir);
  write(dir / "afile", "data\n");
  const Run r = run_vmap({"build", sample, "--out", (dir / "afile").string()});
  CHECK(r.code == 2);
  CHECK(r.err.find("--out: '" + (dir / "afile").string() + "' exists and is not a folder") != std::string::npos);
  CHECK(r.err.find("frames in") == std::string::npos);  // refused before any frame
  CHECK(slurp(dir / "afile") == "data\n");
  const fs::path fresh = dir / "new" / "deeper";
  const Run ok = run_vmap({"build", sample, "--end", "8", "--out", fresh.string(), "--json"});
  INFO(ok.err);
  CHECK(ok.code == 0);
  CHECK(fs::is_regular_file(fresh / "map.vmap"));
  CHECK(fs::is_regular_file(fresh / "contact_sheet.png"));
  const auto j = nlohmann::json::parse(ok.out);
  CHECK(j["files"].size() >= 3);
  CHECK(j["out"] == fresh.string());
}

TEST_CASE("cli: bad input files exit 1 with a one-line message naming them") {
  const fs::path dir = work_dir() / "bad_inputs";
  fs::create_directories(dir);
  const Run missing = run_vmap({"build", (dir / "nothing.txt").string()});
  CHECK(missing.code == 1);
  CHECK(missing.err.find("nothing.txt") != std::string::npos);
  const Run gtdir = run_vmap({"loops", sample, "--gt", dir.string(), "--index", "all"});
  CHECK(gtdir.code == 2);
  CHECK(gtdir.err.find("--gt: '" + dir.string() + "' is a folder") != std::string::npos);
  const Run dev = run_vmap({"loops", sample, "--gt", "/dev/zero", "--index", "all"});
  CHECK(dev.code == 2);
  CHECK(dev.err.find("is not a regular file") != std::string::npos);
  const Run cam = run_vmap({"build", sample, "--camera", (dir / "none.yaml").string()});
  CHECK(cam.code == 2);
  CHECK(cam.err.find("--camera: '") != std::string::npos);
  const Run poses = run_vmap({"localize", "--train", sample, "--poses", dir.string(), "--every-other"});
  CHECK(poses.code == 2);
  CHECK(poses.err.find("--poses: '" + dir.string() + "' is a folder") != std::string::npos);
  write(dir / "broken.jpg", "not an image");
  const Run img = run_vmap({"match", (dir / "broken.jpg").string(), frame_b});
  CHECK(img.code == 1);
  CHECK(img.err.find("broken.jpg") != std::string::npos);
  for (const Run* r : {&missing, &gtdir, &dev, &cam, &poses, &img}) {
    CHECK(r->code != 134);
    CHECK(std::count(r->err.begin(), r->err.end(), '\n') == 1);
  }
}

TEST_CASE("cli: a non-UTF-8 file name with --json gives valid JSON") {
  const fs::path dir = work_dir() / "latin1";
  fs::create_directories(dir);
  const fs::path odd = dir / "caf\xe9.jpg";  // Latin-1 e-acute: not UTF-8
  fs::copy_file(fs::path(VMAP_TEST_SOURCE_DIR) / frame_a, odd);
  const Run r = run_vmap({"match", odd.string(), frame_b, "--json", "--nfeatures", "300"});
  INFO(r.err);
  REQUIRE(r.code == 0);
  const auto j = nlohmann::json::parse(r.out);
  CHECK(j["inputs"][0].get<std::string>().find("caf\xef\xbf\xbd.jpg") != std::string::npos);  // U+FFFD
}

TEST_CASE("cli: build, options from the command line and from --config give the same JSON") {
  same_json({"build", sample}, {"--end", "12", "--nfeatures", "400", "--threshold", "0.4", "--rule", "current", "--json"},
            "end: 12\nnfeatures: 400\nthreshold: 0.4\nrule: current\njson: 1\n", "build");
  // The command line wins over the file.
  const fs::path cfg = work_dir() / "override.yaml";
  write(cfg, "end: 12\nnfeatures: 400\njson: 1\n");
  const Run r = run_vmap({"build", sample, "--config", cfg.string(), "--nfeatures", "300"});
  REQUIRE(r.code == 0);
  const auto j = nlohmann::json::parse(r.out);
  CHECK(j["options"]["nfeatures"] == 300);
  CHECK(j["options"]["end"] == 12);
  // A key that is no option is a usage error.
  write(cfg, "nfeaturez: 400\n");
  usage_error({"build", sample, "--config", cfg.string()}, "--config: 'nfeaturez' is not an option of vmap build");
  usage_error({"build", sample, "--config", (work_dir() / "absent.yaml").string()}, "absent.yaml");
}

TEST_CASE("cli: sweep, command line and --config give the same JSON") {
  same_json({"sweep", sample}, {"--end", "10", "--thresholds", "0.2,0.5", "--features", "akaze", "--json"},
            "sweep:\n  end: 10\n  thresholds: [0.2, 0.5]\n  features: akaze\n  json: 1\n", "sweep");
}

TEST_CASE("cli: match, command line and --config give the same JSON") {
  same_json({"match", frame_a, frame_b}, {"--nfeatures", "500", "--epipolar-px", "2", "--estimator", "ransac", "--json"},
            "nfeatures: 500\nepipolar_px: 2\nestimator: ransac\njson: 1\n", "match");
}

TEST_CASE("cli: loops, command line and --config give the same JSON") {
  const fs::path gt = work_dir() / "gt60.txt";
  std::string rows;
  for (int i = 0; i < 60; ++i) {
    for (int k = 0; k < 60; ++k) rows += k ? " 0" : "0";
    rows += "\n";
  }
  write(gt, rows);
  same_json({"loops", sample, "--gt", gt.string()}, {"--index", "all", "--window", "50", "--nfeatures", "300", "--json"},
            "index: all\nwindow: 50\nnfeatures: 300\njson: 1\n", "loops");
}

TEST_CASE("cli: localize, command line and --config give the same JSON") {
  same_json({"localize", "--room"},
            {"--laps", "1", "--images-per-lap", "8", "--tests", "2", "--neurons", "6", "--lambda", "4", "--words", "16",
             "--json"},
            "laps: 1\nimages_per_lap: 8\ntests: 2\nneurons: 6\nlambda: 4\nwords: 16\njson: 1\n", "localize");
}

TEST_SUITE("data") {
  TEST_CASE("cli: detect, command line and --config give the same JSON; --out writes detections.txt") {
    const std::string model = vmap::test::model_path("yolox_nano.onnx").string();
    const std::string names = vmap::test::model_path("coco80.names").string();
    const fs::path out = work_dir() / "detect_out";
    same_json({"detect", frame_a, "--model", model},
              {"--names", names, "--score", "0.3", "--out", out.string(), "--draw", "--json"},
              "names: " + names + "\nscore: 0.3\nout: " + out.string() + "\ndraw: 1\njson: 1\n", "detect");
    CHECK(fs::is_regular_file(out / "detections.txt"));
    CHECK(fs::is_regular_file(out / "1305031229.528748.png"));
  }
}
