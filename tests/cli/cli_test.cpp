// The `vmap` program as a user runs it: every case starts the built binary, and checks
// its exit code, its message and its JSON. Options given on the command line and in a
// --config file must give the same JSON; every documented error exits with its documented
// code (0 ok, 1 bad input or failed run, 2 usage) and never aborts (134).

#include "support/euroc_layout.hpp"
#include "support/pg_server.hpp"
#include "support/ros2_bags.hpp"
#include "support/shared_data.hpp"

#include <vmap/place/vocabulary.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/io/poses.hpp>

#include <doctest/doctest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <nlohmann/json.hpp>

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <iterator>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <tuple>
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

/// Runs `PREFIX vmap ARGS...` from the repository's root (the docs' working folder), PREFIX
/// a command that runs another (`timeout ...`, `env ...`) or nothing.
Run run_vmap_prefixed(const std::string& prefix, const std::vector<std::string>& args) {
  const fs::path out = work_dir() / "stdout.txt", err = work_dir() / "stderr.txt";
  std::string cmd = "cd " + quote(VMAP_TEST_SOURCE_DIR) + " && " + prefix + " " + quote(VMAP_CLI_BINARY);
  for (const auto& a : args) cmd += " " + quote(a);
  cmd += " >" + quote(out.string()) + " 2>" + quote(err.string()) + " </dev/null";
  const int status = std::system(cmd.c_str());
  Run r;
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  r.out = slurp(out);
  r.err = slurp(err);
  return r;
}

/// Runs `vmap ARGS...` from the repository's root.
Run run_vmap(const std::vector<std::string>& args) { return run_vmap_prefixed("", args); }

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
  CHECK(h.out.find("3 an input does not exist") != std::string::npos);
  CHECK(h.out.find("8 a write failed") != std::string::npos);
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
  usage_error({"localize"}, "give --room, --train or --memory");
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
  usage_error({"loops", sample, "--gt", (dir / "gt" / "pr.csv").string(), "--rank", "brute_force", "--out",
               (dir / "gt").string()},
              "is also an input");
  CHECK(slurp(dir / "gt" / "pr.csv") == "0\n");
}

TEST_CASE("cli: a symbolic link as an output file is refused") {
  const fs::path dir = work_dir() / "symlink_out";
  fs::create_directories(dir / "out");
  write(dir / "target.csv", "keep\n");
  fs::create_symlink(dir / "target.csv", dir / "out" / "pr.csv");
  // The old spellings (--index, all) still work, each with a note naming the new one.
  const Run old = run_vmap({"loops", sample, "--gt", (dir / "target.csv").string(), "--index", "all", "--out",
                            (dir / "out").string()});
  INFO("stderr: " << old.err);
  CHECK(old.code == 2);
  CHECK(old.err.find("is a symbolic link") != std::string::npos);
  CHECK(old.err.find("vmap loops: note: --index is now --rank; --index will be removed in the next release") !=
        std::string::npos);
  CHECK(old.err.find("vmap loops: note: --rank all is now --rank brute_force; all will be removed in the next "
                     "release") != std::string::npos);
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

TEST_CASE("cli: the exit code tells a missing input (3), a damaged memory (4) and a newer one (5)") {
  const fs::path dir = work_dir() / "exit_codes";
  fs::create_directories(dir);
  const auto failed = [](const Run& r, int code, const std::string& message) {
    INFO("stderr: " << r.err);
    CHECK(r.code == code);
    CHECK(r.err.find(message) != std::string::npos);
    CHECK(std::count(r.err.begin(), r.err.end(), '\n') == 1);
  };
  failed(run_vmap({"build", (dir / "no_such_folder").string()}), 3, "does not exist");
  // A store whose pages are not SQLite's (a damaged file with the right first bytes).
  const fs::path store = dir / "damaged.vmdb";
  write(store, std::string("SQLite format 3") + '\0' + std::string(4096, 'm'));
  failed(run_vmap({"memory", "info", store.string()}), 4, store.string());
  // A memory file cut inside its header, and one of a format version this build does not
  // read (the u32 after the magic).
  const fs::path cut = dir / "cut.vmem";
  write(cut, std::string("VMAPMEMO") + std::string(4, '\0'));
  failed(run_vmap({"memory", "info", cut.string()}), 4, "cut.vmem");
  const fs::path newer = dir / "newer.vmem";
  write(newer, std::string("VMAPMEMO") + std::string("\x63\0\0\0", 4) + std::string(64, '\0'));
  failed(run_vmap({"memory", "info", newer.string()}), 5, "format version 99 is not supported");
}

TEST_CASE("cli: bad input files exit 1 (3 when missing) with a one-line message naming them") {
  const fs::path dir = work_dir() / "bad_inputs";
  fs::create_directories(dir);
  const Run missing = run_vmap({"build", (dir / "nothing.txt").string()});
  CHECK(missing.code == 3);
  CHECK(missing.err.find("nothing.txt") != std::string::npos);
  const Run gtdir = run_vmap({"loops", sample, "--gt", dir.string(), "--rank", "brute_force"});
  CHECK(gtdir.code == 2);
  CHECK(gtdir.err.find("--gt: '" + dir.string() + "' is a folder") != std::string::npos);
  const Run dev = run_vmap({"loops", sample, "--gt", "/dev/zero", "--rank", "brute_force"});
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
  same_json({"loops", sample, "--gt", gt.string()},
            {"--rank", "brute_force", "--window", "50", "--nfeatures", "300", "--json"},
            "rank: brute_force\nwindow: 50\nnfeatures: 300\njson: 1\n", "loops");
}

TEST_CASE("cli: localize, command line and --config give the same JSON") {
  same_json({"localize", "--room"},
            {"--laps", "1", "--images-per-lap", "8", "--tests", "2", "--neurons", "6", "--lambda", "4", "--words", "16",
             "--json"},
            "laps: 1\nimages_per_lap: 8\ntests: 2\nneurons: 6\nlambda: 4\nwords: 16\njson: 1\n", "localize");
}

// ---- visual memory: build --memory / --resume, localize --memory, loops --memory ------

namespace {

/// One memory of the 60 sample frames per process (the vocabulary learned from the first
/// 10 key images, so that loop detection runs on so short a sequence), with the JSON of
/// the run that built it.
const std::pair<fs::path, nlohmann::json>& sample_memory() {
  static const std::pair<fs::path, nlohmann::json> built = [] {
    const fs::path dir = work_dir() / "memory_one_run";
    const Run r = run_vmap({"build", sample, "--memory", dir.string() + "/", "--vocabulary-after", "10",
                            "--json"});
    INFO(r.err);
    REQUIRE(r.code == 0);
    return std::pair{dir / "memory.vmdb", nlohmann::json::parse(r.out)};
  }();
  return built;
}

}  // namespace

TEST_CASE("cli: build --memory DIR/ writes DIR/memory.vmdb; --resume continues it with the same key images") {
  const auto& [one_file, one] = sample_memory();
  CHECK(fs::is_regular_file(one_file));
  CHECK(one["frames"] == 60);
  CHECK(one["memory"]["file"] == one_file.string());
  CHECK(one["memory"]["resumed"] == false);
  CHECK(one["memory"]["pushed"] == 60);
  CHECK(one["memory"]["last_frame_index"] == 59);
  CHECK(one["memory"]["bytes"] == fs::file_size(one_file));
  CHECK(one["key_frames"].size() == one["key_images"].get<std::size_t>());
  CHECK(one["key_images"].get<std::size_t>() >= 12);
  CHECK(one["out"].is_null());
  // Interrupted after 30 frames (written at every key image and every 10 frames), resumed
  // in a second process with --out.
  const fs::path file = work_dir() / "memory_resumed" / "sample.vmdb";
  const Run first = run_vmap({"build", sample, "--memory", file.string(), "--vocabulary-after", "10", "--end",
                              "30", "--save-every", "10", "--json"});
  INFO(first.err);
  REQUIRE(first.code == 0);
  const auto j1 = nlohmann::json::parse(first.out);
  CHECK(j1["memory"]["saves"].get<std::size_t>() >= j1["key_images"].get<std::size_t>());
  CHECK(j1["memory"]["last_frame_index"] == 29);
  const fs::path out = work_dir() / "memory_resumed_out";
  const Run second = run_vmap({"build", sample, "--memory", file.string(), "--resume", "--out", out.string(), "--json"});
  INFO(second.err);
  REQUIRE(second.code == 0);
  const auto j2 = nlohmann::json::parse(second.out);
  CHECK(j2["memory"]["resumed"] == true);
  CHECK(j2["memory"]["pushed"] == 30);
  CHECK(j2["frames"] == 60);
  CHECK(j2["memory"]["last_frame_index"] == 59);
  CHECK(j2["key_frames"] == one["key_frames"]);
  CHECK(j2["memory"]["loops"] == one["memory"]["loops"]);
  // --out keeps working beside the memory: the pictures of every key image.
  CHECK(fs::is_regular_file(out / "map.vmap"));
  CHECK(fs::is_regular_file(out / "contact_sheet.png"));
  CHECK(j2["files"].size() == 5);  // the pictures, key_images.txt and the memory's loops.txt
  CHECK(fs::is_regular_file(out / "loops.txt"));
  // Nothing left to read: a usage error, the memory unchanged.
  const std::string before = slurp(file);
  usage_error({"build", sample, "--memory", file.string(), "--resume", "--end", "60"}, "already holds every frame");
  CHECK(slurp(file) == before);
}

TEST_CASE("cli: --working-memory 2 reads older key images from the memory and gives the same memory and map") {
  const auto build = [](const std::string& name, const std::string& working) {
    const fs::path file = work_dir() / name / "sample.vmdb";
    const fs::path out = work_dir() / (name + "_out");
    const Run r = run_vmap({"build", sample, "--memory", file.string(), "--vocabulary-after", "10", "--working-memory",
                            working, "--out", out.string(), "--json"});
    INFO(r.err);
    REQUIRE(r.code == 0);
    const Run info = run_vmap({"memory", "info", file.string(), "--json"});
    REQUIRE(info.code == 0);
    return std::tuple{nlohmann::json::parse(r.out), nlohmann::json::parse(info.out), slurp(out / "map.vmap")};
  };
  const auto [bounded, bounded_info, bounded_map] = build("working_memory_2", "2");
  const auto [whole, whole_info, whole_map] = build("working_memory_all", "0");
  const auto& [one_file, one] = sample_memory();  // the default working memory
  REQUIRE(whole["key_images"].get<std::size_t>() > 2);
  CHECK(bounded["key_frames"] == whole["key_frames"]);
  CHECK(bounded["key_frames"] == one["key_frames"]);
  CHECK(bounded["memory"]["loops"] == whole["memory"]["loops"]);
  CHECK(bounded_info == whole_info);
  // map.vmap of --out holds every key image's features, also those read back.
  CHECK(bounded_map == whole_map);
  // Stopped after 30 frames and resumed holding 2 key images' features (the older ones
  // loaded without them): the memory of the uninterrupted run.
  const fs::path resumed = work_dir() / "working_memory_resumed" / "sample.vmdb";
  const Run first = run_vmap({"build", sample, "--memory", resumed.string(), "--vocabulary-after", "10",
                              "--working-memory", "2", "--end", "30"});
  INFO(first.err);
  REQUIRE(first.code == 0);
  const Run second = run_vmap({"build", sample, "--memory", resumed.string(), "--resume", "--working-memory", "2", "--json"});
  INFO(second.err);
  REQUIRE(second.code == 0);
  CHECK(nlohmann::json::parse(second.out)["key_frames"] == whole["key_frames"]);
  const Run resumed_info = run_vmap({"memory", "info", resumed.string(), "--json"});
  REQUIRE(resumed_info.code == 0);
  CHECK(nlohmann::json::parse(resumed_info.out) == whole_info);
  usage_error({"build", sample, "--working-memory", "2"}, "--working-memory needs --memory");
}

TEST_CASE("cli: build --memory keeps the chance rate given, else the one measured for the descriptor") {
  const fs::path dir = work_dir() / "memory_chance_rate";
  fs::create_directories(dir);
  const auto rate_of = [&](const std::string& name, const std::vector<std::string>& options) {
    std::vector<std::string> args{"build", sample, "--memory", (dir / name).string(), "--end", "8", "--force"};
    args.insert(args.end(), options.begin(), options.end());
    const Run b = run_vmap(args);
    INFO(b.err);
    REQUIRE(b.code == 0);
    const Run l = run_vmap({"localize", "--memory", (dir / name).string(), frame_a, "--json"});
    INFO(l.err);
    REQUIRE(l.code == 0);
    return nlohmann::json::parse(l.out)["chance_inlier_rate"].get<double>();
  };
  CHECK(rate_of("given.vmdb", {"--chance-rate", "0.05"}) == 0.05);
  CHECK(rate_of("sift.vmdb", {"--features", "sift"}) == 0.032);
  CHECK(rate_of("orb.vmdb", {}) == 0.1);
}

TEST_CASE("cli: build --memory errors: mixed options, --resume without a memory, a non-memory file") {
  const fs::path dir = work_dir() / "memory_errors";
  fs::create_directories(dir);
  const std::string mem = (dir / "m.vmdb").string();
  usage_error({"build", sample, "--resume"}, "--resume needs --memory DIR|FILE");
  usage_error({"build", sample, "--save-every", "5"}, "--save-every needs --memory");
  usage_error({"build", sample, "--images", "png"}, "--images needs --memory");
  usage_error({"build", sample, "--chance-rate", "0.05"}, "--chance-rate needs --memory");
  usage_error({"build", sample, "--memory", mem, "--chance-rate", "2"}, "--chance-rate");
  usage_error({"loops", sample, "--chance-rate", "0"}, "--chance-rate");
  usage_error({"build", sample, "--memory", mem, "--resume"}, "--resume: no memory file '" + mem + "' to continue");
  usage_error({"build", sample, "--memory", mem, "--resume", "--threshold", "0.4"}, "--resume and --threshold conflict");
  usage_error({"build", sample, "--memory", mem, "--vocabulary", mem, "--vocabulary-after", "3"},
              "--vocabulary and --vocabulary-after conflict");
  usage_error({"build", sample, "--memory", sample}, "is also an input");
  usage_error({"build", sample, "--memory", (dir / "out" / "m.vmdb").string(), "--out", (dir / "out").string()},
              "is inside the --out folder");
  CHECK(!fs::exists(mem));
  write(dir / "notes.txt", "keep\n");  // an existing file that is no memory is not replaced
  usage_error({"build", sample, "--memory", (dir / "notes.txt").string()}, "exists and is not a vmap memory");
  CHECK(slurp(dir / "notes.txt") == "keep\n");
  write(dir / "not_memory.vmdb", "VMAPMAP! this is no memory file at all");
  const Run bad = run_vmap({"build", sample, "--memory", (dir / "not_memory.vmdb").string(), "--resume"});
  CHECK(bad.code == 4);
  CHECK(bad.err.find("not a vmap memory") != std::string::npos);
  CHECK(std::count(bad.err.begin(), bad.err.end(), '\n') == 1);
}

TEST_CASE("cli: --resume of a list whose frames changed since (same path, first frame and stride) is refused") {
  const fs::path dir = work_dir() / "resume_changed";
  fs::create_directories(dir);
  // The first 30 frames of the sample list, listed with absolute paths.
  const fs::path rgb = fs::path(VMAP_TEST_SOURCE_DIR) / "examples/data/tum_fr1_rpy_60/rgb";
  std::vector<fs::path> frames;
  for (const auto& e : fs::directory_iterator(rgb)) frames.push_back(e.path());
  std::sort(frames.begin(), frames.end());
  const auto list_of = [&](std::size_t first, std::size_t n, std::size_t skip_from) {
    std::string text;
    for (std::size_t i = first, k = 0; k < n; ++i)
      if (i < skip_from || i % 2 == 0) {
        text += frames[i].string() + "\n";
        ++k;
      }
    return text;
  };
  const fs::path list = dir / "frames.txt", mem = dir / "m.vmdb";
  write(list, list_of(0, 30, 60));
  REQUIRE(run_vmap({"build", list.string(), "--memory", mem.string(), "--end", "20"}).code == 0);
  // The same first frame, the later frames every other one: the last key image's frame
  // is another image now.
  write(list, list_of(0, 30, 2));
  usage_error({"build", list.string(), "--memory", mem.string(), "--resume"},
              "--resume: the input '" + fs::weakly_canonical(list).string() + "' changed since the memory '" +
                  mem.string() + "' read it: its frame ");
  // Shorter than the memory's frames.
  write(list, list_of(0, 12, 60));
  usage_error({"build", list.string(), "--memory", mem.string(), "--resume"}, "it now has 12 frames");
  // As it was: the run resumes.
  write(list, list_of(0, 30, 60));
  CHECK(run_vmap({"build", list.string(), "--memory", mem.string(), "--resume"}).code == 0);
}

TEST_CASE("cli: localize --memory answers every query with its place decision; --json lists every answer") {
  const auto& [file, built] = sample_memory();
  const auto keys = built["key_frames"].get<std::vector<std::size_t>>();
  // Frame 0 is the first key image; frame_b is frame 1, one frame later.
  const Run r = run_vmap({"localize", "--memory", file.string(), frame_a, frame_b, "--json"});
  INFO(r.err);
  REQUIRE(r.code == 0);
  const auto j = nlohmann::json::parse(r.out);
  CHECK(j["command"] == "localize");
  CHECK(j["memory"] == file.string());
  CHECK(j["key_images"] == keys.size());
  CHECK(j["localized"] == 2);
  REQUIRE(j["queries"].size() == 2);
  CHECK(j["min_confidence"] == 0.5);
  CHECK(j["chance_inlier_rate"] == 0.1);  // ORB's measured rate, the default
  for (const auto& q : j["queries"]) {
    CHECK(q["status"] == "accepted");
    CHECK(q["localized"] == true);
    CHECK(q["confidence"].get<double>() >= 0.5);
    CHECK(q["confidence"].get<double>() <= 1.0);
    CHECK(q["reason"].get<std::string>().rfind("confidence ", 0) == 0);
    CHECK(q["reason_code"] == "confidence reaches the threshold");
    CHECK(q["evidence"]["inliers"].get<int>() >= 12);
    CHECK(q["evidence"]["inlier_ratio"].get<double>() > 0.0);
    CHECK(q["evidence"]["significance"].get<double>() > 0.0);
    CHECK(q["evidence"]["spread"].get<double>() > 0.0);
    CHECK(q["evidence"]["model"] == "fundamental");
    REQUIRE(!q["matches"].empty());
    CHECK(q["key"] == q["matches"][0]["key"]);
    const auto& best = q["matches"][0];
    const auto key = best["key"].get<std::size_t>();
    REQUIRE(key < keys.size());
    CHECK(best["frame_index"] == keys[key]);
    CHECK(best["frame_index"].get<std::size_t>() <= 5);  // the queries are frames 0 and 1
    CHECK(best["inliers"].get<int>() == q["evidence"]["inliers"].get<int>());
    CHECK(best["confidence"] == q["confidence"]);
    CHECK(best["inliers"].get<int>() <= best["matches"].get<int>());
    CHECK(best["bow_score"].get<double>() > 0.0);
    CHECK(best["bow_score"].get<double>() <= 1.0);
    CHECK(best["model"].size() == 9);
    CHECK(best["model_kind"] == "fundamental");
    CHECK(best["pose"].is_null());  // built from images alone: no odometry
    for (std::size_t m = 1; m < q["matches"].size(); ++m)  // every verified key image, most confident first
      CHECK(q["matches"][m]["confidence"].get<double>() <= q["matches"][m - 1]["confidence"].get<double>());
  }
  // The query identical to key image 0 (frame 0) answers it.
  CHECK(j["queries"][0]["matches"][0]["key"] == 0);
  CHECK(j["queries"][0]["matches"][0]["name"] == "1305031229.528748.jpg");
  const Run text = run_vmap({"localize", "--memory", file.string(), frame_a});
  REQUIRE(text.code == 0);
  CHECK(text.out.find(frame_a + ": key 0 (frame 0, 1305031229.528748.jpg), confidence ") != std::string::npos);
  // A threshold no evidence reaches: "unknown place", with the reason, and still exit 0.
  // (A frame that is not a key image: its confidence is below 1.)
  std::string frame_30;
  {
    std::ifstream list(std::string(VMAP_TEST_SOURCE_DIR) + "/examples/data/tum_fr1_rpy_60/rgb.txt");
    std::string line;
    std::size_t k = 0;
    while (std::getline(list, line)) {
      if (line.empty() || line[0] == '#') continue;
      if (k >= 30 && std::find(keys.begin(), keys.end(), k) == keys.end()) {
        frame_30 = "examples/data/tum_fr1_rpy_60/" + line.substr(line.find(' ') + 1);
        break;
      }
      ++k;
    }
  }
  REQUIRE(!frame_30.empty());
  const Run strict = run_vmap({"localize", "--memory", file.string(), frame_30, "--min-confidence", "1", "--json"});
  INFO(strict.err);
  REQUIRE(strict.code == 0);
  const auto sj = nlohmann::json::parse(strict.out);
  CHECK(sj["localized"] == 0);
  CHECK(sj["queries"][0]["status"] == "unknown place");
  CHECK(sj["queries"][0]["key"].is_null());
  CHECK(sj["queries"][0]["reason"].get<std::string>().find("< 1.00") != std::string::npos);
  CHECK(sj["queries"][0]["reason_code"] == "confidence below the threshold");
  const Run strict_text = run_vmap({"localize", "--memory", file.string(), frame_30, "--min-confidence", "1"});
  REQUIRE(strict_text.code == 0);
  CHECK(strict_text.out.find(frame_30 + ": unknown place (confidence ") != std::string::npos);
  usage_error({"localize", "--memory", file.string(), frame_a, "--min-confidence", "1.5"}, "--min-confidence");
  // `vmap memory localize` shares the code: the same answers.
  const Run same = run_vmap({"memory", "localize", file.string(), frame_a, frame_b, "--json"});
  REQUIRE(same.code == 0);
  auto a = nlohmann::json::parse(same.out), b = j;
  for (auto* x : {&a, &b})
    for (auto& q : (*x)["queries"]) q.erase("ms");
  CHECK(a == b);
}

TEST_CASE("cli: localize --memory --sequence answers each query with its neighbours; memory localize too") {
  const auto& file = sample_memory().first;
  const Run alone = run_vmap({"localize", "--memory", file.string(), sample, "--json"});
  const Run seq = run_vmap({"localize", "--memory", file.string(), sample, "--json", "--sequence", "8"});
  INFO(seq.err);
  REQUIRE(alone.code == 0);
  REQUIRE(seq.code == 0);
  const auto a = nlohmann::json::parse(alone.out), s = nlohmann::json::parse(seq.out);
  CHECK(a["sequence"] == 1);
  CHECK(s["sequence"] == 8);
  REQUIRE(s["queries"].size() == 60);
  for (std::size_t i = 0; i < 60; ++i) {
    CAPTURE(i);
    const auto& q = s["queries"][i];
    CHECK(a["queries"][i]["sequence"].is_null());
    REQUIRE(q["sequence"].is_object());
    CHECK(q["sequence"]["window"] == 8);
    CHECK(q["sequence"]["on_line"].get<int>() <= q["sequence"]["weighed"].get<int>());
    CHECK(q["sequence"]["single_confidence"] == a["queries"][i]["confidence"]);
    // The sample frames are the memory's: each is accepted alone, and the sequence keeps
    // the key image it was accepted at.
    CHECK(a["queries"][i]["localized"] == true);
    CHECK(q["localized"] == true);
    CHECK(q["key"] == a["queries"][i]["key"]);
  }
  const Run text = run_vmap({"memory", "localize", file.string(), sample, "--sequence", "4", "--max-speed", "2"});
  INFO(text.err);
  REQUIRE(text.code == 0);
  CHECK(text.out.find("  sequence: 4 of 4 images that see a place on the line (window 4); alone: confidence 1.00") !=
        std::string::npos);
  usage_error({"localize", "--memory", file.string(), sample, "--max-speed", "2"}, "--max-speed needs --sequence N with N > 1");
  usage_error({"localize", "--memory", file.string(), sample, "--sequence", "0"}, "--sequence");
  usage_error({"localize", "--memory", file.string(), sample, "--sequence", "101"}, "--sequence");
  usage_error({"memory", "localize", file.string(), sample, "--sequence", "2", "--max-speed", "-1"}, "--max-speed");
  usage_error({"localize", "--room", "--sequence", "3"}, "--sequence is an option of --memory");
}

TEST_CASE("cli: localize --memory errors: mixed modes, no image, missing or non-memory file") {
  const auto& file = sample_memory().first;
  usage_error({"localize", "--memory", file.string(), frame_a, "--room"}, "--memory and --room conflict");
  usage_error({"localize", "--memory", file.string(), frame_a, "--train", sample}, "--memory and --train conflict");
  usage_error({"localize", "--memory", file.string()}, "--memory needs query images");
  usage_error({"localize", "--room", frame_a}, "query images on the command line need --memory M");
  const fs::path missing = work_dir() / "no_such.vmdb";
  usage_error({"localize", "--memory", missing.string(), frame_a}, "--memory: '" + missing.string() + "' does not exist");
  const Run bad = run_vmap({"localize", "--memory", sample, frame_a});
  CHECK(bad.code == 4);
  CHECK(bad.err.find("'" + sample + "' is not a vmap memory") != std::string::npos);
  // A list, a folder or a video of queries: each frame a query, in order.
  const Run list = run_vmap({"localize", "--memory", file.string(), sample, "--json"});
  INFO(list.err);
  REQUIRE(list.code == 0);
  const auto answers = nlohmann::json::parse(list.out)["queries"];
  REQUIRE(answers.size() == 60);
  CHECK(answers[0]["image"] == "1305031229.528748.jpg");
  CHECK(answers[0]["key"] == 0);
  const Run folder = run_vmap({"localize", "--memory", file.string(), "examples/data/tum_fr1_rpy_60/rgb"});
  CHECK(folder.code == 0);
  CHECK(std::count(folder.out.begin(), folder.out.end(), '\n') >= 60);
  // One image that cannot be read is an Error naming it.
  const Run img = run_vmap({"localize", "--memory", file.string(), (work_dir() / "no_such.jpg").string()});
  CHECK(img.code == 3);
  CHECK(img.err.find("query image '" + (work_dir() / "no_such.jpg").string() + "': ") != std::string::npos);
  usage_error({"memory", "localise", file.string(), frame_a}, "unknown subcommand 'localise'; did you mean 'memory localize'?");
}

TEST_CASE("cli: loops --memory prints the memory's loop edges; --gt evaluates them over the key images") {
  const auto& [file, built] = sample_memory();
  const auto keys = built["key_frames"].get<std::vector<std::size_t>>();
  const Run r = run_vmap({"loops", "--memory", file.string(), "--json"});
  INFO(r.err);
  REQUIRE(r.code == 0);
  const auto j = nlohmann::json::parse(r.out);
  CHECK(j["frames"] == 60);
  CHECK(j["key_images"] == keys.size());
  CHECK(j["loops"].size() == built["memory"]["loops"].get<std::size_t>());
  // The sample frames: a hand-held camera turning on one spot. Its chain of key images
  // changes views, so it is not stationary, and its returns to an earlier view are loops.
  CHECK_FALSE(j["loops"].empty());
  CHECK(j["stationary"] == false);
  for (const auto& l : j["loops"]) {
    const auto from = l["from"].get<std::size_t>(), to = l["to"].get<std::size_t>();
    REQUIRE(from < keys.size());
    CHECK(to + 10 < from);  // the memory's loop window
    CHECK(l["query"] == keys[from]);
    CHECK(l["match"] == keys[to]);
    CHECK(l["confidence"].get<double>() >= j["min_confidence"].get<double>());
    CHECK(l["bow_score"].get<double>() > 0.0);
  }
  // A ground truth over the 60 frames that marks the memory's loop edges and one pair
  // more (the last key image's frame against the first's, which it does not claim): every
  // edge true, recall the edges over the edges plus one.
  REQUIRE(keys.size() > 11);
  const std::size_t q = keys.back(), m = keys.front();
  std::vector<std::vector<int>> marked(60, std::vector<int>(60, 0));
  for (const auto& l : j["loops"]) marked[l["query"].get<std::size_t>()][l["match"].get<std::size_t>()] = 1;
  const std::size_t edges = j["loops"].size();
  REQUIRE(marked[q][m] == 0);
  marked[q][m] = 1;
  std::string rows;
  for (std::size_t i = 0; i < 60; ++i) {
    for (std::size_t k = 0; k < 60; ++k) rows += std::string(k ? " " : "") + (marked[i][k] ? "1" : "0");
    rows += "\n";
  }
  const fs::path gt = work_dir() / "memory_gt.txt";
  write(gt, rows);
  const Run e = run_vmap({"loops", "--memory", file.string(), "--gt", gt.string(), "--json"});
  INFO(e.err);
  REQUIRE(e.code == 0);
  const auto ej = nlohmann::json::parse(e.out);
  CAPTURE(ej.dump());
  // Each key image is a query with its most confident edge (lcd/evaluation.hpp).
  std::set<std::size_t> queries;
  for (const auto& l : j["loops"]) queries.insert(l["from"].get<std::size_t>());
  CHECK(ej["false_positives"] == 0);
  CHECK(ej["true_positives"] == queries.size());
  queries.insert(keys.size() - 1);
  CHECK(ej["loops_gt"] == queries.size());
  CHECK(ej["true_edges"] == edges);
  CHECK(ej["precision"] == 1.0);
  const Run text = run_vmap({"loops", "--memory", file.string()});
  REQUIRE(text.code == 0);
  CHECK(text.out.find(std::to_string(j["loops"].size()) + " loop edges (confidence >= 0.50)") != std::string::npos);
  CHECK(text.out.find("the camera never left its place") == std::string::npos);
  const auto edge_lines = [](const std::string& out) {
    std::size_t lines = 0;
    for (auto at = out.find(") -> key "); at != std::string::npos; at = out.find(") -> key ", at + 1)) ++lines;
    return lines;
  };
  CHECK(edge_lines(text.out) == std::min<std::size_t>(j["loops"].size(), 5));  // a summary: the 5 most confident
  const Run every = run_vmap({"loops", "--memory", file.string(), "--edges"});
  REQUIRE(every.code == 0);
  CHECK(edge_lines(every.out) == j["loops"].size());
  // Errors: the sequence mode's input and options, no input at all, a non-memory file.
  usage_error({"loops", sample, "--memory", file.string()}, "--memory and INPUT conflict");
  usage_error({"loops", "--memory", file.string(), "--rank", "brute_force"}, "--memory and --rank conflict");
  usage_error({"loops"}, "give INPUT (the frames) or --memory M");
  const Run bad = run_vmap({"loops", "--memory", gt.string()});
  CHECK(bad.code == 4);
  CHECK(bad.err.find("not a vmap memory") != std::string::npos);
  // A ground truth smaller than the memory's frames is refused, naming --gt.
  write(gt, "0 0\n0 0\n");
  const Run small = run_vmap({"loops", "--memory", file.string(), "--gt", gt.string()});
  CHECK(small.code == 1);
  CHECK(small.err.find("--gt: '" + gt.string() + "' covers 2 frames") != std::string::npos);
}

TEST_CASE("cli: memory build / info share the memory code: a folder means DIR/memory.vmdb") {
  const auto& [file, built] = sample_memory();
  const Run r = run_vmap({"memory", "info", file.parent_path().string(), "--json"});
  INFO(r.err);
  REQUIRE(r.code == 0);
  const auto j = nlohmann::json::parse(r.out);
  CHECK(j["frames"] == 60);
  CHECK(j["last_frame_index"] == 59);
  CHECK(j["key_images"].size() == built["key_frames"].size());
  CHECK(j["key_images"][0]["frame_index"] == 0);
  CHECK(j["loops"].size() == built["memory"]["loops"].get<std::size_t>());
  usage_error({"memory", "build", sample, "--memory", (work_dir() / "none.vmdb").string(), "--resume"},
              "--resume: no memory file");
}

TEST_CASE("cli: vocabulary without frames or convert without files are usage errors") {
  usage_error({"vocabulary"}, "learning needs FRAMES and --out");
  usage_error({"vocabulary", "convert", (work_dir() / "missing.txt").string(), "x.vmapvoc"}, "INPUT");
  usage_error({"vocabulary", "convert"}, "INPUT");
  const fs::path folder = work_dir();
  const Run r = run_vmap({"vocabulary", "convert", folder.string(), (folder / "x.vmapvoc").string()});
  CHECK(r.code != 0);
}

namespace {

std::string file_bytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

/// A small binary vocabulary, learned on random descriptors (no frames to read).
vmap::AnyVocabulary tiny_vocabulary() {
  cv::Mat d(200, 32, CV_8UC1);
  cv::randu(d, cv::Scalar(0), cv::Scalar(256));
  return vmap::AnyVocabulary::learn({d}, {.branching = 3, .depth = 2, .seed = 1});
}

}  // namespace

TEST_CASE("cli: vocabulary convert never replaces its input, a memory or any file but a vocabulary (--force)") {
  const fs::path dir = work_dir() / "convert_outputs";
  fs::create_directories(dir);
  const auto v = tiny_vocabulary();
  const fs::path voc = dir / "voc.vmapvoc", other = dir / "other.vmapvoc", fbow = dir / "voc.fbow";
  v.save(voc);
  v.save(other);
  v.save(fbow);
  // A gzipped DBoW2 file converted onto itself: refused, the file as it was.
  const fs::path gz = dir / "d.yml.gz";
  write(gz, "\x1f\x8b not really gzip, but the command must not touch it");
  const fs::path memory = dir / "mem.vmdb";
  write(memory, std::string("SQLite format 3") + '\0' + std::string(100, 'm'));
  const fs::path notes = dir / "notes.txt";
  write(notes, "10 my notes, which start with a number\n");
  fs::create_symlink(voc, dir / "link.vmapvoc");
  const std::string voc_bytes = file_bytes(voc), gz_bytes = file_bytes(gz), memory_bytes = file_bytes(memory),
                    notes_bytes = file_bytes(notes);
  const auto refused = [&](const std::vector<std::string>& args, const std::string& message) {
    const Run r = run_vmap(args);
    INFO("stderr: " << r.err);
    CHECK(r.code == 1);
    CHECK(r.err.find(message) != std::string::npos);
  };
  for (const bool force : {false, true}) {
    CAPTURE(force);
    const auto with = [&](std::vector<std::string> args) {
      if (force) args.push_back("--force");
      return args;
    };
    // An output that is the input is a usage error (exit 2), also through a link.
    for (const fs::path& same : {gz, voc, dir / "link.vmapvoc"}) {
      const Run r = run_vmap(with({"vocabulary", "convert", same == gz ? gz.string() : voc.string(), same.string()}));
      INFO("stderr: " << r.err);
      CHECK(r.code == 2);
      CHECK(r.err.find("OUTPUT: '" + same.string() + "' is also an input") != std::string::npos);
    }
    refused(with({"vocabulary", "convert", fbow.string(), memory.string()}),
            force ? "exists and is not a vocabulary vmap reads, so it is not replaced" : "already exists");
    refused(with({"vocabulary", "convert", voc.string(), notes.string()}),
            force ? "exists and is not a vocabulary vmap reads, so it is not replaced" : "already exists");
    refused(with({"vocabulary", "convert", voc.string(), dir.string()}), "is a folder, expected a file");
    refused(with({"vocabulary", "convert", voc.string(), "/dev/null"}), "is not a regular file");
  }
  refused({"vocabulary", "convert", voc.string(), other.string()}, "already exists; it is replaced only when asked to (--force)");
  CHECK(file_bytes(voc) == voc_bytes);
  CHECK(file_bytes(gz) == gz_bytes);
  CHECK(file_bytes(memory) == memory_bytes);
  CHECK(file_bytes(notes) == notes_bytes);
  CHECK(fs::is_symlink(dir / "link.vmapvoc"));
  // --force replaces another vocabulary (recognised by content, whatever its name).
  const Run r = run_vmap({"vocabulary", "convert", fbow.string(), other.string(), "--force"});
  INFO(r.err);
  CHECK(r.code == 0);
  CHECK(vmap::AnyVocabulary::load(other).size() == v.size());
}

TEST_CASE("cli: vocabulary --out follows the same rule, checked before any frame is read") {
  const fs::path dir = work_dir() / "learn_outputs";
  fs::create_directories(dir);
  const fs::path memory = dir / "mem.vmdb";
  write(memory, std::string("SQLite format 3") + '\0' + std::string(100, 'm'));
  const std::string memory_bytes = file_bytes(memory);
  for (const bool force : {false, true}) {
    std::vector<std::string> args{"vocabulary", sample, "--out", memory.string(), "--words", "8", "--depth", "1"};
    if (force) args.push_back("--force");
    const Run r = run_vmap(args);
    INFO(r.err);
    CHECK(r.code == 1);
    CHECK(r.err.find(force ? "exists and is not a vocabulary vmap reads" : "already exists") != std::string::npos);
  }
  CHECK(file_bytes(memory) == memory_bytes);
  // Its own frames' list as --out: a usage error, the list as it was.
  const std::string list = file_bytes(fs::path(VMAP_TEST_SOURCE_DIR) / sample);
  const Run same = run_vmap({"vocabulary", sample, "--out", sample, "--words", "8", "--depth", "1", "--force"});
  CHECK(same.code == 2);
  CHECK(same.err.find("--out: '" + sample + "' is also an input") != std::string::npos);
  CHECK(file_bytes(fs::path(VMAP_TEST_SOURCE_DIR) / sample) == list);
}

TEST_SUITE("data") {
  TEST_CASE("cli: localize --memory of another place answers \"unknown place\" with its reason, exit 0") {
    const auto& file = sample_memory().first;
    const std::string kitti = vmap::test::data_path("kitti07_160/image_0/000050.png").string();
    const std::string corridor = vmap::test::data_path("rtabmap_loop/images/30.jpg").string();
    const Run r = run_vmap({"localize", "--memory", file.string(), kitti, corridor, "--json"});
    INFO(r.err);
    REQUIRE(r.code == 0);
    const auto j = nlohmann::json::parse(r.out);
    CHECK(j["localized"] == 0);
    for (const auto& q : j["queries"]) {
      CHECK(q["status"] != "accepted");
      CHECK(q["localized"] == false);
      CHECK(q["key"].is_null());
      CHECK(!q["reason"].get<std::string>().empty());
      CHECK(q["confidence"].get<double>() < 0.5);
    }
    const Run text = run_vmap({"localize", "--memory", file.string(), kitti});
    REQUIRE(text.code == 0);
    CHECK(text.out.find(kitti + ": ") != std::string::npos);
    CHECK(text.out.find(", key ") == std::string::npos);
  }

  TEST_CASE("cli: vocabulary convert reads ORB-SLAM2, DBoW2 and FBoW files and writes each format back") {
    const fs::path dir = work_dir();
    for (const char* name : {"orbslam2_k10L3.txt", "dbow2_k10L3.yml.gz", "fbow_k10L3.fbow"}) {
      const std::string in = vmap::test::data_path(std::string("vocabularies/") + name).string();
      const fs::path out = dir / (std::string(name) + ".vmapvoc");
      const Run r = run_vmap({"vocabulary", "convert", in, out.string()});
      INFO(name << ": " << r.err);
      REQUIRE(r.code == 0);
      CHECK(r.out.find("1000 words (branching 10, depth 3") != std::string::npos);
      const auto v = vmap::AnyVocabulary::load(out);
      CHECK(v.size() == 1000);
    }
    // vmap's file to ORBvoc text: DBoW2's node order, so the shared file comes back line
    // for line but for the weights' last digit (6 significant digits both ways)
    const Run t = run_vmap({"vocabulary", "convert", (dir / "orbslam2_k10L3.txt.vmapvoc").string(), (dir / "again.txt").string()});
    REQUIRE(t.code == 0);
    const auto a = vmap::AnyVocabulary::load(dir / "again.txt");
    const auto b = vmap::AnyVocabulary::load(dir / "orbslam2_k10L3.txt.vmapvoc");
    CHECK(cv::norm(a.binary()->words(), b.binary()->words(), cv::NORM_L1) == 0.0);
    CHECK(a.binary()->idf() == b.binary()->idf());
    const Run f = run_vmap({"vocabulary", "convert", (dir / "fbow_k10L3.fbow.vmapvoc").string(), (dir / "again.fbow").string()});
    REQUIRE(f.code == 0);
    CHECK(vmap::AnyVocabulary::load(dir / "again.fbow").binary()->serialize() ==
          vmap::AnyVocabulary::load(dir / "fbow_k10L3.fbow.vmapvoc").binary()->serialize());
  }

  TEST_CASE("cli: build --memory --poses keeps each key image's pose; localize --memory answers it") {
    const std::string gt = vmap::test::data_path("tum_fr1_rpy/groundtruth.txt").string();
    const fs::path file = work_dir() / "memory_poses.vmdb";
    const Run b = run_vmap({"build", sample, "--memory", file.string(), "--poses", gt, "--end", "12", "--json"});
    INFO(b.err);
    REQUIRE(b.code == 0);
    const Run r = run_vmap({"localize", "--memory", file.string(), frame_a, "--json"});
    INFO(r.err);
    REQUIRE(r.code == 0);
    const auto best = nlohmann::json::parse(r.out)["queries"][0]["matches"][0];
    REQUIRE(best["key"] == 0);
    // Frame 0 (time 1305031229.528748) takes the ground-truth pose nearest in time:
    // line 360 of groundtruth.txt, 1305031229.5332 1.2989 0.6880 1.5734 (qx qy qz qw).
    const auto se3 = best["pose"]["se3"].get<std::vector<double>>();
    REQUIRE(se3.size() == 12);
    CHECK(se3[3] == doctest::Approx(1.2989).epsilon(1e-9));
    CHECK(se3[7] == doctest::Approx(0.6880).epsilon(1e-9));
    CHECK(se3[11] == doctest::Approx(1.5734).epsilon(1e-9));
    // The rotation is orthonormal (the file's quaternion, normalised).
    for (int i = 0; i < 3; ++i)
      CHECK(se3[4 * i] * se3[4 * i] + se3[4 * i + 1] * se3[4 * i + 1] + se3[4 * i + 2] * se3[4 * i + 2] ==
            doctest::Approx(1.0).epsilon(1e-9));
    const Run text = run_vmap({"localize", "--memory", file.string(), frame_a});
    CHECK(text.out.find(", position (1.299, 0.688, 1.573), ") != std::string::npos);
    CHECK(nlohmann::json::parse(r.out)["queries"][0]["position"].is_null());  // no GCS trained
    usage_error({"build", sample, "--poses", gt}, "--poses needs --memory");
  }

  TEST_CASE("cli: localize --memory answers the query's metric pose (JSON, text, --trajectory); without a camera it says so once") {
    // The sample without every 5th frame, with the motion capture's poses and the camera.
    const std::string gt = vmap::test::data_path("tum_fr1_rpy/groundtruth.txt").string();
    const fs::path dir = work_dir() / "metric_pose";
    fs::remove_all(dir);
    fs::create_directories(dir);
    const std::string mem = (dir / "m.vmdb").string();
    const std::string sequence = (dir / "held.txt").string();
    {
      // The kept frames as a TUM rgb.txt (their times, for the poses), the held-out ones
      // as a list of images (the queries).
      std::ifstream in(fs::path(VMAP_TEST_SOURCE_DIR) / sample);
      std::ofstream kept(dir / "kept_rgb.txt"), held(sequence);
      const std::string folder = (fs::path(VMAP_TEST_SOURCE_DIR) / "examples/data/tum_fr1_rpy_60").string();
      std::size_t i = 0;
      for (std::string line; std::getline(in, line);) {
        if (line.empty() || line[0] == '#') continue;
        const std::string image = folder + "/" + line.substr(line.find(' ') + 1);
        if (i++ % 5 == 2)
          held << image << "\n";
        else
          kept << line.substr(0, line.find(' ')) << " " << image << "\n";
      }
    }
    const Run b = run_vmap({"build", (dir / "kept_rgb.txt").string(), "--memory", mem, "--poses", gt, "--camera",
                            "examples/data/tum_fr1_camera.yaml"});
    INFO(b.err);
    REQUIRE(b.code == 0);
    std::vector<std::string> queries;
    {
      std::ifstream held(sequence);
      for (std::string line; std::getline(held, line);) queries.push_back(line);
    }
    REQUIRE(queries.size() == 12);
    const std::string trajectory = (dir / "poses.tum").string();
    std::vector<std::string> args{"localize", "--memory", mem, "--json", "--trajectory", trajectory};
    args.insert(args.end(), queries.begin(), queries.end());
    const Run l = run_vmap(args);
    INFO(l.err);
    REQUIRE(l.code == 0);
    const auto j = nlohmann::json::parse(l.out);
    const auto truth = vmap::load_camera_poses(gt);
    std::size_t posed = 0;
    for (const auto& q : j["queries"]) {
      REQUIRE(q.contains("pose"));
      REQUIRE(q["pose_reason"].is_string());
      if (q["pose"].is_null()) {
        CHECK(q["pose_reason_code"] != "posed");
        continue;
      }
      ++posed;
      CHECK(q["pose_reason_code"] == "posed");
      const auto p = q["pose"]["position"].get<std::vector<double>>();
      const auto r = q["pose"]["quaternion"].get<std::vector<double>>();
      REQUIRE(p.size() == 3);
      REQUIRE(r.size() == 4);
      CHECK(r[0] * r[0] + r[1] * r[1] + r[2] * r[2] + r[3] * r[3] == doctest::Approx(1.0).epsilon(1e-9));
      CHECK(r[3] >= 0.0);  // TUM's order, qw last
      CHECK(q["pose"]["covariance"].size() == 6);
      CHECK(q["pose"]["inliers"].get<int>() >= 12);
      // Within 5 cm of the motion capture at the query's time (the image's name).
      const double time = q["time"].get<double>();
      CHECK(time == doctest::Approx(std::stod(fs::path(q["image"].get<std::string>()).stem().string())).epsilon(1e-12));
      const auto at = vmap::poses_for_frames(truth, {time}, "groundtruth.txt", 0.05, false).front();
      CHECK(cv::norm(cv::Vec3d(p[0], p[1], p[2]) - at.position) < 0.05);
    }
    CHECK(posed >= 8);
    CHECK(j["posed"] == posed);
    CHECK(j["trajectory"]["poses"] == posed);
    // The trajectory: the answered poses with the queries' times, read back by vmap's TUM reader.
    const auto back = vmap::load_tum_poses(trajectory);
    REQUIRE(back.size() == posed);
    std::size_t k = 0;
    for (const auto& q : j["queries"]) {
      if (q["pose"].is_null()) continue;
      CHECK(back[k].timestamp == doctest::Approx(q["time"].get<double>()).epsilon(1e-12));
      CHECK(back[k].position[0] == doctest::Approx(q["pose"]["position"][0].get<double>()).epsilon(1e-9));
      ++k;
    }
    // The text: a pose line under the key image's.
    const Run text = run_vmap({"localize", "--memory", mem, queries[0], queries[1]});
    CHECK(text.out.find("  pose: position (") != std::string::npos);
    // As a sequence of 8: a pose per image, no gross error.
    std::vector<std::string> seq_args{"localize", "--memory", mem, sequence, "--sequence", "8", "--json"};
    const Run s = run_vmap(seq_args);
    INFO(s.err);
    REQUIRE(s.code == 0);
    for (const auto& q : nlohmann::json::parse(s.out)["queries"]) CHECK(q.contains("pose"));
    // A memory with poses and no camera: no pose, and one message that says how to get one.
    const std::string plain = (dir / "plain.vmdb").string();
    REQUIRE(run_vmap({"build", (dir / "kept_rgb.txt").string(), "--memory", plain, "--poses", gt}).code == 0);
    const Run n = run_vmap({"localize", "--memory", plain, queries[0], queries[1], "--json"});
    REQUIRE(n.code == 0);
    const std::string said = "has poses but no camera";
    REQUIRE(n.err.find(said) != std::string::npos);
    CHECK(n.err.find(said, n.err.find(said) + 1) == std::string::npos);
    CHECK(n.err.find("--camera FILE") != std::string::npos);
    for (const auto& q : nlohmann::json::parse(n.out)["queries"]) {
      CHECK(q["pose"].is_null());
      if (q["localized"].get<bool>()) CHECK(q["pose_reason_code"] == "no camera");
    }
    usage_error({"localize", "--train", sample, "--poses", gt, "--every-other", "--trajectory", trajectory},
                "--trajectory is an option of --memory");
    // A fleet's robot built from the same frames answers the same poses: the metric pose is
    // the memory's, whichever store holds it.
    if (auto* server = vmap::test::test_server()) {
      const std::string uri = server->uri("cli_metric_pose");
      const Run fb = run_vmap({"build", (dir / "kept_rgb.txt").string(), "--memory", uri, "--robot", "r", "--poses", gt,
                               "--camera", "examples/data/tum_fr1_camera.yaml"});
      INFO(fb.err);
      REQUIRE(fb.code == 0);
      std::vector<std::string> fleet_args{"localize", "--memory", uri, "--robot", "r", "--json"};
      fleet_args.insert(fleet_args.end(), queries.begin(), queries.end());
      const Run fl = run_vmap(fleet_args);
      INFO(fl.err);
      REQUIRE(fl.code == 0);
      const auto fj = nlohmann::json::parse(fl.out);
      CHECK(fj["posed"] == posed);
      REQUIRE(fj["queries"].size() == j["queries"].size());
      for (std::size_t i = 0; i < queries.size(); ++i) {
        const auto& in_file = j["queries"][i];
        const auto& in_fleet = fj["queries"][i];
        CHECK(in_fleet["pose_reason_code"] == in_file["pose_reason_code"]);
        if (in_file["pose"].is_null() || in_fleet["pose"].is_null()) continue;
        for (int c = 0; c < 3; ++c)
          CHECK(in_fleet["pose"]["position"][c].get<double>() ==
                doctest::Approx(in_file["pose"]["position"][c].get<double>()).epsilon(1e-6));
      }
    }
  }

  TEST_CASE("cli: build --memory --poses --gcs keeps floor poses and trains the GCS; localize answers a position") {
    const std::string gt = vmap::test::data_path("tum_fr1_rpy/groundtruth.txt").string();
    const fs::path file = work_dir() / "memory_gcs.vmdb";
    const Run b = run_vmap({"build", sample, "--memory", file.string(), "--poses", gt, "--gcs", "--end", "30"});
    INFO(b.err);
    REQUIRE(b.code == 0);
    const Run r = run_vmap({"localize", "--memory", file.string(), frame_a, "--json"});
    INFO(r.err);
    REQUIRE(r.code == 0);
    const auto q = nlohmann::json::parse(r.out)["queries"][0];
    // Key image 0 keeps frame 0's floor pose (z-up: x, y of the ground-truth line 360).
    REQUIRE(q["matches"][0]["key"] == 0);
    CHECK(q["matches"][0]["pose"]["x"].get<double>() == doctest::Approx(1.2989).epsilon(1e-9));
    CHECK(q["matches"][0]["pose"]["y"].get<double>() == doctest::Approx(0.6880).epsilon(1e-9));
    // The GCS position of frame 0: the first 30 frames of fr1/rpy stay within a few cm
    // of where they start (the camera mostly rotates), so the answer is within 5 cm.
    REQUIRE(q["position"].is_object());
    CHECK(std::abs(q["position"]["x"].get<double>() - 1.2989) < 0.05);
    CHECK(std::abs(q["position"]["y"].get<double>() - 0.6880) < 0.05);
    const Run text = run_vmap({"localize", "--memory", file.string(), frame_a});
    CHECK(text.out.find("GCS position (") != std::string::npos);
    usage_error({"build", sample, "--memory", (work_dir() / "gcs_nop.vmdb").string(), "--gcs"}, "--gcs needs --poses");
    usage_error({"build", sample, "--gcs"}, "--gcs needs --memory");
  }

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

namespace {

/// The first bytes of a PNG file whose header claims `width` x `height` pixels (no
/// pixel data: the size is refused from the header, before any decoding).
std::string png_header(std::uint32_t width, std::uint32_t height) {
  std::string b = "\x89PNG\r\n\x1a\n";
  b += std::string("\0\0\0\x0d", 4) + "IHDR";
  for (std::uint32_t v : {width, height})
    for (int shift = 24; shift >= 0; shift -= 8) b += static_cast<char>((v >> shift) & 0xFF);
  b += std::string("\x08\x02\0\0\0", 5) + std::string(4, '\0');
  return b + std::string(64, '\0');
}

/// A fresh folder under the work folder.
fs::path fresh_dir(const std::string& name) {
  const fs::path d = work_dir() / name;
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

/// `vmap ARGS` exits with `code` and one line naming `message`, never a crash.
Run fails_with(const std::vector<std::string>& args, int code, const std::string& message) {
  const Run r = run_vmap(args);
  INFO("stderr: " << r.err);
  CHECK(r.code == code);
  CHECK(r.err.find(message) != std::string::npos);
  CHECK(std::count(r.err.begin(), r.err.end(), '\n') <= 2);  // the message (and the --help hint)
  return r;
}

}  // namespace

TEST_CASE("cli: YAML nested 40000 levels deep is refused before OpenCV parses it, as --config and --camera") {
  const fs::path dir = fresh_dir("deep_yaml");
  const std::string deep = std::string(40000, '[') + std::string(40000, ']');
  write(dir / "config.yaml", "threshold: " + deep + "\n");
  write(dir / "camera.yaml", "%YAML:1.0\nCamera.fx: " + deep + "\n");
  write(dir / "dashes.yaml", "%YAML:1.0\nintrinsics:\n" + [] {
    std::string s;
    for (int i = 0; i < 40000; ++i) s += "- ";
    return s + "1\n";
  }());
  fails_with({"build", sample, "--config", (dir / "config.yaml").string()}, 2,
             "--config: YAML nested 40001 levels deep, more than the 32 accepted");
  fails_with({"build", sample, "--camera", (dir / "camera.yaml").string()}, 1,
             (dir / "camera.yaml").string() + ": YAML nested 40001 levels deep, more than the 32 accepted");
  fails_with({"build", sample, "--camera", (dir / "dashes.yaml").string()}, 1, "levels deep, more than the 32 accepted");
  write(dir / "big.yaml", "# " + std::string(std::size_t{2} << 20, 'x') + "\n");
  fails_with({"build", sample, "--config", (dir / "big.yaml").string()}, 2, "more than the 1048576 a settings file may have");
  // OpenCV 4.6's parser never returns on the first (refused before it parses) and throws
  // std::length_error on the second (found by the fuzz targets): both usage errors.
  write(dir / "dash.yaml", "----e\ns\n");
  fails_with({"build", sample, "--config", (dir / "dash.yaml").string()}, 2,
             "--config: line 1 starts with '-' at the top level, where a key is expected");
  write(dir / "length.yaml", "features: or&\nnuild:\n  json: 0\n  : 0.4\n");
  fails_with({"build", sample, "--config", (dir / "length.yaml").string()}, 2, "--config: not a valid YAML file (");
}

TEST_CASE("cli: --config and query images that are devices, FIFOs or too many pixels are refused unread") {
  const fs::path dir = fresh_dir("unbounded");
  fails_with({"build", sample, "--config", "/dev/zero"}, 2, "--config: '/dev/zero' is not a regular file");
  const fs::path fifo = dir / "fifo";
  REQUIRE(::mkfifo(fifo.c_str(), 0600) == 0);
  fails_with({"build", sample, "--config", fifo.string()}, 2, "--config: '" + fifo.string() + "' is not a regular file");
  fails_with({"build", sample, "--config", ""}, 2, "--config: the file name is empty");
  const std::string mem = sample_memory().first.string();
  fails_with({"localize", "--memory", mem, fifo.string()}, 1, "query image '" + fifo.string() + "': is not a regular file");
  write(dir / "huge.png", png_header(20000, 20000));
  fails_with({"localize", "--memory", mem, (dir / "huge.png").string()}, 1,
             "query image '" + (dir / "huge.png").string() + "': the image is 20000x20000 pixels, more than the limit");
  write(dir / "huger.png", png_header(32000, 32000));
  fails_with({"match", (dir / "huger.png").string(), frame_b}, 1, "image '" + (dir / "huger.png").string() + "': the image is 32000x32000 pixels, more than the limit");
}

TEST_CASE("cli: a YAML map where an option takes a value, and empty values, are usage errors") {
  const fs::path dir = fresh_dir("silent");
  write(dir / "map.yaml", "threshold: {value: 0.9}\n");
  fails_with({"build", sample, "--config", (dir / "map.yaml").string()}, 2,
             "--config: the value of 'threshold' is a map; an option takes a number, a string or a list of them");
  write(dir / "section.yaml", "build:\n  threshold: {value: 0.9}\n");
  fails_with({"build", sample, "--config", (dir / "section.yaml").string()}, 2, "the value of 'threshold' is a map");
  write(dir / "other.yaml", "loops:\n  rank: brute_force\nbuild:\n  end: 8\n");  // another subcommand's section is fine
  const Run ok = run_vmap({"build", sample, "--config", (dir / "other.yaml").string(), "--json"});
  INFO(ok.err);
  CHECK(ok.code == 0);
  fails_with({"localize", "--memory", "", frame_a}, 2, "--memory: the value is empty");
  fails_with({"build", sample, "--camera", ""}, 2, "--camera: the value is empty");
  write(dir / "empty_value.yaml", "camera: \"\"\n");
  fails_with({"build", sample, "--config", (dir / "empty_value.yaml").string()}, 2, "--camera: the value is empty");
}

TEST_CASE("cli: calibrations without physical sense are refused, naming the file and the value") {
  const fs::path dir = fresh_dir("absurd_camera");
  const std::string pinhole = "%YAML:1.0\nCamera.fy: 500\nCamera.cx: 320\nCamera.cy: 240\n";
  write(dir / "fx.yaml", pinhole + "Camera.fx: 1e-300\n");
  fails_with({"build", sample, "--camera", (dir / "fx.yaml").string()}, 1,
             (dir / "fx.yaml").string() + ": focal lengths fx = 1e-300, fy = 500 pixels are outside [1, 1e+06]");
  write(dir / "k1.yaml", pinhole + "Camera.fx: 500\nCamera.k1: 1e300\nCamera.k2: 0\nCamera.p1: 0\nCamera.p2: 0\n");
  fails_with({"build", sample, "--camera", (dir / "k1.yaml").string()}, 1,
             "distortion coefficient 0 = 1e+300 is outside [-1000, 1000]");
  const std::string ros = "camera_matrix: {rows: 3, cols: 3, data: [500, 0, 320, 0, 500, 240, 0, 0, 1]}\n";
  write(dir / "width.yaml", ros + "image_width: 2147483647\nimage_height: 480\n");
  fails_with({"build", sample, "--camera", (dir / "width.yaml").string()}, 1,
             "the image size 2147483647 x 480 exceeds 65536 pixels a side");
  write(dir / "centre.yaml", ros + "image_width: 320\nimage_height: 200\n");
  fails_with({"build", sample, "--camera", (dir / "centre.yaml").string()}, 1,
             "the principal point (320, 240) lies outside the 320 x 200 image");
  write(dir / "size.yaml", "camera_matrix: {rows: 3, cols: 3, data: [250, 0, 160, 0, 250, 120, 0, 0, 1]}\n"
                           "image_width: 320\nimage_height: 240\n");
  fails_with({"build", sample, "--end", "5", "--camera", (dir / "size.yaml").string()}, 1,
             "--camera " + (dir / "size.yaml").string() +
                 ": the calibration is for 320 x 240 images, the frames are 640 x 480");
}

TEST_CASE("cli: no memory is lost to --out, and a refused or failed run leaves no empty folder") {
  const fs::path dir = fresh_dir("out_keeps_memory");
  const fs::path maps = dir / "maps";
  REQUIRE(run_vmap({"build", sample, "--end", "6", "--out", maps.string()}).code == 0);
  // A memory is never placed in an --out folder (the next --out run replaces it whole).
  fails_with({"build", sample, "--end", "6", "--memory", maps.string() + "/"}, 2,
             "--memory: '" + maps.string() + "' is an --out folder of vmap");
  CHECK(!fs::exists(maps / "memory.vmdb"));
  // An --out folder that gained a file vmap did not write there is not replaced.
  write(maps / "notes.txt", "mine\n");
  fails_with({"build", sample, "--end", "6", "--out", maps.string()}, 2,
             "holds 'notes.txt', which is not one of the files vmap wrote there");
  CHECK(slurp(maps / "notes.txt") == "mine\n");
  // A folder marked by an older vmap (no list of files) that holds a memory: refused.
  const fs::path old = dir / "old";
  fs::create_directories(old);
  write(old / ".vmap-output", "written by vmap; the folder is replaced as a whole\n");
  fs::copy_file(sample_memory().first, old / "memory.vmdb");
  fails_with({"build", sample, "--end", "6", "--out", old.string()}, 2, "holds 'memory.vmdb'");
  CHECK(fs::file_size(old / "memory.vmdb") == fs::file_size(sample_memory().first));
  // Refused or failed runs remove the folders they created.
  const fs::path fresh = dir / "new" / "deeper";
  fails_with({"build", (dir / "missing.txt").string(), "--out", fresh.string()}, 3, "missing.txt");
  CHECK(!fs::exists(dir / "new"));
  write(dir / "bad.yaml", "%YAML:1.0\nCamera.fx: 1e-300\nCamera.fy: 500\nCamera.cx: 320\nCamera.cy: 240\n");
  fails_with({"build", sample, "--out", fresh.string(), "--camera", (dir / "bad.yaml").string()}, 1, "focal lengths");
  CHECK(!fs::exists(dir / "new"));
  fails_with({"build", sample, "--memory", (dir / "memnew" / "m.vmdb").string(), "--camera", (dir / "bad.yaml").string()},
             1, "focal lengths");
  CHECK(!fs::exists(dir / "memnew"));
}

TEST_CASE("cli: a misspelt option gets a suggestion; another subcommand's option names its subcommands") {
  fails_with({"build", sample, "--treshold", "0.3"}, 2, "unknown option '--treshold'; did you mean '--threshold'?");
  fails_with({"build", sample, "--treshold=0.3"}, 2, "unknown option '--treshold'; did you mean '--threshold'?");
  fails_with({"loops", sample, "--camera", "x.yaml"}, 2,
             "option '--camera' is not an option of 'vmap loops'; it belongs to: build, match, sweep");
  fails_with({"localize", "--room", "--images", "2"}, 2,
             "option '--images' is not an option of 'vmap localize'; it belongs to: build");
  fails_with({"build", sample, "--zzzzzzzzzz"}, 2, "unknown option '--zzzzzzzzzz' (see vmap build --help)");
}

TEST_CASE("cli: a camera that rests is reported stationary by loops and by a memory, and closes no loop") {
  // One sample frame repeated 24 times with seeded sensor noise (sigma 2) and sub-pixel
  // jitter: the chain never changes views.
  const fs::path dir = fresh_dir("still_clip");
  const cv::Mat base = cv::imread(
      (vmap::test::source_dir() / "examples/data/tum_fr1_rpy_60/rgb/1305031229.528748.jpg").string(), cv::IMREAD_GRAYSCALE);
  REQUIRE_FALSE(base.empty());
  cv::RNG rng(5);
  for (int i = 0; i < 24; ++i) {
    cv::Mat moved, noise(base.size(), CV_16SC1), wide;
    cv::warpAffine(base, moved, cv::Matx23d(1, 0, rng.uniform(-0.5, 0.5), 0, 1, rng.uniform(-0.5, 0.5)), base.size(),
                   cv::INTER_LINEAR, cv::BORDER_REFLECT);
    rng.fill(noise, cv::RNG::NORMAL, 0, 2.0);
    moved.convertTo(wide, CV_16SC1);
    wide += noise;
    wide.convertTo(moved, CV_8UC1);
    char name[32];
    std::snprintf(name, sizeof name, "%03d.png", i);
    REQUIRE(cv::imwrite((dir / name).string(), moved));
  }
  const Run loops = run_vmap({"loops", dir.string(), "--json"});
  INFO(loops.err);
  REQUIRE(loops.code == 0);
  const auto lj = nlohmann::json::parse(loops.out);
  CHECK(lj["stationary"] == true);
  CHECK(lj["loops"].empty());
  const fs::path file = work_dir() / "still_clip.vmdb";
  const Run build = run_vmap({"build", dir.string(), "--memory", file.string(), "--vocabulary-after", "5", "--json"});
  INFO(build.err);
  REQUIRE(build.code == 0);
  CHECK(nlohmann::json::parse(build.out)["key_images"] == 1);
  const Run text = run_vmap({"loops", "--memory", file.string()});
  REQUIRE(text.code == 0);
  CHECK(text.out.find("the camera never left its place") != std::string::npos);
  const Run info = run_vmap({"memory", "info", file.string(), "--json"});
  REQUIRE(info.code == 0);
  CHECK(nlohmann::json::parse(info.out)["stationary"] == true);
}

TEST_CASE("cli: memory info and loops --memory summarise the loop edges; --edges lists each with names and times") {
  const auto& [file, built] = sample_memory();
  const Run j = run_vmap({"memory", "info", file.string(), "--json"});
  REQUIRE(j.code == 0);
  const auto info = nlohmann::json::parse(j.out);
  const std::size_t edges = info["loops"].size();
  // The sample clip is a camera turning on one spot: a line says so (stationary).
  const std::size_t said = info["stationary"].get<bool>() ? 1 : 0;
  for (const auto& l : info["loops"]) {
    const auto& key = info["key_images"][l["from"].get<std::size_t>()];
    CHECK(l["query_name"] == key["name"]);
    CHECK(l["query_time"].is_number());
  }
  const Run all = run_vmap({"memory", "info", file.string(), "--edges"});
  REQUIRE(all.code == 0);
  CHECK(static_cast<std::size_t>(std::count(all.out.begin(), all.out.end(), '\n')) == 1 + said + edges);
  const Run summary = run_vmap({"memory", "info", file.string()});
  REQUIRE(summary.code == 0);
  CHECK(static_cast<std::size_t>(std::count(summary.out.begin(), summary.out.end(), '\n')) ==
        1 + said + (edges <= 5 ? edges : 6));
  const Run loops = run_vmap({"loops", "--memory", file.string(), "--edges"});
  REQUIRE(loops.code == 0);
  CHECK(static_cast<std::size_t>(std::count(loops.out.begin(), loops.out.end(), '\n')) == 2 + said + edges);
}

TEST_CASE("cli: memory export writes key images with names and times, and loop edges as timestamp pairs") {
  const auto& file = sample_memory().first;
  const fs::path out = fresh_dir("memory_export") / "exported";
  const Run r = run_vmap({"memory", "export", file.string(), "--out", out.string(), "--json"});
  INFO(r.err);
  REQUIRE(r.code == 0);
  const auto info = nlohmann::json::parse(run_vmap({"memory", "info", file.string(), "--json"}).out);
  std::istringstream keys(slurp(out / "key_images.txt"));
  std::string line;
  std::getline(keys, line);
  CHECK(line == "# frame_index name timestamp");
  for (const auto& k : info["key_images"]) {
    REQUIRE(std::getline(keys, line));
    std::istringstream row(line);
    std::size_t index = 0;
    std::string name;
    double t = -1;
    row >> index >> name >> t;
    CHECK(index == k["frame_index"].get<std::size_t>());
    CHECK(name == k["name"].get<std::string>());
    // The sample's names are their TUM times: 1305031229.528748.jpg is at 1305031229.528748 s.
    CHECK(std::abs(t - std::stod(name.substr(0, name.size() - 4))) < 1e-6);
  }
  std::istringstream pairs(slurp(out / "loops.txt"));
  std::getline(pairs, line);
  CHECK(line == "# query_time match_time query_name match_name inliers");
  for (const auto& l : info["loops"]) {
    REQUIRE(std::getline(pairs, line));
    std::istringstream row(line);
    double tq = 0, tm = 0;
    std::string nq, nm;
    int inliers = 0;
    row >> tq >> tm >> nq >> nm >> inliers;
    CHECK(nq == l["query_name"].get<std::string>());
    CHECK(nm == l["match_name"].get<std::string>());
    CHECK(std::abs(tq - l["query_time"].get<double>()) < 1e-6);
    CHECK(inliers == l["inliers"].get<int>());
  }
  CHECK(!fs::exists(out / "key_images.tum"));  // no poses in this memory
  fails_with({"memory", "export", file.string()}, 2, "--out is required");

  // A full disk (bash's file size limit of 0: no byte can be written): a failed write (exit 8, not a
  // usage error) that leaves no half-written folder behind.
  const fs::path full = out.parent_path() / "full";
  const std::string inner = "trap '' XFSZ; ulimit -f 0; exec " + quote(VMAP_CLI_BINARY) + " memory export " +
                            quote(file.string()) + " --out " + quote(full.string()) + " >/dev/null 2>/dev/null";
  const int status = std::system(("bash -c " + quote(inner)).c_str());
  CHECK(WEXITSTATUS(status) == 8);
  CHECK(!fs::exists(full));
  for (const auto& e : fs::directory_iterator(out.parent_path()))
    CHECK(e.path().filename().string().find(".vmap-") == std::string::npos);
}

TEST_CASE("cli: key_images.txt of build --out gives each key image's name and time") {
  const fs::path out = fresh_dir("keys_named") / "out";
  REQUIRE(run_vmap({"build", sample, "--end", "10", "--out", out.string()}).code == 0);
  std::istringstream keys(slurp(out / "key_images.txt"));
  std::string line;
  std::getline(keys, line);
  CHECK(line == "# frame_index name timestamp");
  REQUIRE(std::getline(keys, line));
  CHECK(line == "0 1305031229.528748.jpg 1305031229.528748");
}

TEST_SUITE("data") {
  TEST_CASE("cli: a EuRoC folder runs as it is: build with sensor.yaml, loops with EuRoC ground truth") {
    const fs::path mav0 = vmap::test::make_euroc_layout(fresh_dir("euroc"), vmap::test::data_path("tum_fr1_rpy/rgb.txt"),
                                                        120, vmap::test::data_path("tum_fr1_rpy/groundtruth.txt"));
    const std::string cam0 = (mav0 / "cam0").string();
    const Run b = run_vmap({"build", cam0, "--camera", cam0 + "/sensor.yaml", "--end", "30", "--json"});
    INFO(b.err);
    REQUIRE(b.code == 0);
    const auto j = nlohmann::json::parse(b.out);
    CHECK(j["frames"] == 30);
    const Run csv = run_vmap({"build", cam0 + "/data.csv", "--end", "30", "--json"});
    REQUIRE(csv.code == 0);
    CHECK(without_times(nlohmann::json::parse(csv.out))["key_images"] == without_times(j)["key_images"]);
    // The recording's top folder holds one sequence per camera: the error names them.
    fails_with({"build", mav0.string()}, 1, "it is a EuRoC recording: give one of its camera folders (" + cam0 + ")");
    const std::string gt = (mav0 / "state_groundtruth_estimate0" / "data.csv").string();
    const Run loops = run_vmap({"loops", cam0, "--gt-poses", gt, "--json"});
    INFO(loops.err);
    CHECK(loops.code == 0);
    // The frames' clock shifted by an hour: the error names both time ranges.
    fails_with({"loops", cam0, "--gt-poses", gt, "--time-offset", "3600"}, 1,
               "no pose within 0.050000 s of frame 0 (time 1305034829.528748 s); the ");
    // Poses and memory exports: key_images.tum is read back by vmap's TUM reader, and
    // the g2o edges join key images with their relative pose.
    const fs::path out = fresh_dir("euroc_memory");
    const Run m = run_vmap({"build", cam0, "--memory", (out / "m.vmdb").string(), "--poses", gt, "--vocabulary-after",
                            "10", "--out", (out / "pictures").string(), "--json"});
    INFO(m.err);
    REQUIRE(m.code == 0);
    const auto tum = vmap::load_tum_poses(out / "pictures" / "key_images.tum");
    const auto info = nlohmann::json::parse(run_vmap({"memory", "info", (out / "m.vmdb").string(), "--json"}).out);
    REQUIRE(tum.size() == info["key_images"].size());
    const auto truth = vmap::load_camera_poses(gt);
    for (std::size_t k = 0; k < tum.size(); ++k) {
      const auto se3 = info["key_images"][k]["pose"]["se3"].get<std::vector<double>>();
      CHECK(tum[k].position[0] == doctest::Approx(se3[3]).epsilon(1e-9));
      CHECK(tum[k].position[2] == doctest::Approx(se3[11]).epsilon(1e-9));
      const auto near = vmap::associate_by_timestamp(truth, {tum[k].timestamp}, 0.05).front();
      REQUIRE(near);
      CHECK(cv::norm(truth[*near].position - tum[k].position) < 1e-9);
    }
    std::istringstream g2o(slurp(out / "pictures" / "loops.g2o"));
    std::size_t vertices = 0, edges = 0;
    for (std::string line; std::getline(g2o, line);) {
      std::istringstream row(line);
      std::vector<std::string> t;
      for (std::string s; row >> s;) t.push_back(s);
      if (t[0] == "VERTEX_SE3:QUAT") {
        REQUIRE(t.size() == 9);
        const auto& p = tum[vertices];
        CHECK(std::stod(t[2]) == doctest::Approx(p.position[0]).epsilon(1e-9));
        ++vertices;
      } else {
        REQUIRE(t[0] == "EDGE_SE3:QUAT");
        REQUIRE(t.size() == 31);
        const auto from = std::stoul(t[1]), to = std::stoul(t[2]);
        const auto& a = tum[from];
        const auto& b2 = tum[to];
        const cv::Vec3d d = a.rotation.t() * (b2.position - a.position);
        for (int k = 0; k < 3; ++k) CHECK(std::stod(t[3 + static_cast<std::size_t>(k)]) == doctest::Approx(d[k]).epsilon(1e-6));
        ++edges;
      }
    }
    CHECK(vertices == tum.size());
    // An odometry edge between consecutive key images; the loops need a camera for their
    // metric pose, which this memory has not.
    CHECK(edges == tum.size() - 1);
  }
}

TEST_CASE("cli: vocabulary value errors exit 2 before any frame is read; one summary line to a non-terminal") {
  const std::string out = (work_dir() / "v.vmapvoc").string();
  usage_error({"vocabulary", sample, "--out", out, "--depth", "0"}, "--depth: must be >= 1, got '0'");
  usage_error({"vocabulary", sample, "--out", out, "--words", "0"}, "--words: must be >= 2, got '0'");
  usage_error({"vocabulary", sample, "--out", out, "--nfeatures", "-5"}, "--nfeatures: must be >= 1, got '-5'");
  usage_error({"vocabulary", sample, "--out", out, "--words", "99999999999999999999"}, "--words: must be <= 100000000");
  // A branching above the tree's 4096: refused before the features are extracted.
  const Run wide = run_vmap({"vocabulary", sample, "--out", out, "--words", "100000000", "--depth", "2"});
  CHECK(wide.code == 2);
  CHECK(wide.err.find("--words 100000000 with --depth 2 needs a branching above 4096") != std::string::npos);
  CHECK(wide.err.find("features") == std::string::npos);
  usage_error({"loops", sample, "--words", "100000000", "--depth", "1"}, "needs a branching above 4096");
  CHECK(!fs::exists(out));

  // stderr is a file here: no carriage return, at most the one summary line of the run.
  const Run r = run_vmap({"vocabulary", sample, "--out", out, "--words", "64", "--depth", "2"});
  INFO(r.err);
  REQUIRE(r.code == 0);
  CHECK(r.err.find('\r') == std::string::npos);
  CHECK(std::count(r.err.begin(), r.err.end(), '\n') <= 1);
  CHECK(r.out.find(out + ": ") == 0);
}

TEST_SUITE("data") {
  TEST_CASE("cli: calibrate measures a stack's chance rate on places that share nothing, the same for a seed") {
    const std::string corridor = vmap::test::data_path("rtabmap_loop/images").string();
    const std::string cabinet = vmap::test::data_path("tum_fr3_cabinet_kf/rgb.txt").string();
    const Run a = run_vmap({"calibrate", corridor, cabinet, "--json"});
    INFO(a.err);
    REQUIRE(a.code == 0);
    const auto j = nlohmann::json::parse(a.out);
    CHECK(j["frames"] == nlohmann::json::array({84, 58}));
    CHECK(j["pairs"] == 200);
    CHECK(j["measured_chance_rate"] == 0.1);
    // ORB's rate on these two places: near the 0.1 the decision was built with.
    CHECK(j["rate"].get<double>() > 0.05);
    CHECK(j["rate"].get<double>() < 0.2);
    CHECK(j["weighed"].get<int>() > 0);
    CHECK(j["strongest_significance"].get<double>() >= 5.0);
    const Run again = run_vmap({"calibrate", corridor, cabinet, "--json"});
    CHECK(nlohmann::json::parse(again.out)["rate"] == j["rate"]);
    const Run other = run_vmap({"calibrate", corridor, cabinet, "--seed", "2", "--json"});
    CHECK(nlohmann::json::parse(other.out)["rate"] != j["rate"]);
    const Run human = run_vmap({"calibrate", corridor, cabinet});
    CHECK(human.code == 0);
    CHECK(human.out.find("chance rate   ") != std::string::npos);
    CHECK(human.out.find("--chance-rate") != std::string::npos);
    usage_error({"calibrate", corridor}, "give at least two places");
    const Run same = run_vmap({"calibrate", corridor, corridor});
    CHECK(same.code != 0);
    CHECK(same.err.find("the places share views") != std::string::npos);
    CHECK(same.err.find("vmap calibrate: error: chance calibration: the foreign pairs fit") != std::string::npos);
    usage_error({"calibrate", corridor, cabinet, "--pairs", "10"}, "--pairs");
  }

  TEST_CASE("cli: the sample memory's loop edges are all true by the motion-capture poses") {
    // The hand-held camera turns on one spot and returns to earlier views: each loop edge
    // is a pair of frames within 0.5 m and 30 degrees (the ground truth's defaults).
    const auto& [file, built] = sample_memory();
    const Run e = run_vmap({"loops", "--memory", file.string(), "--gt-poses",
                            vmap::test::data_path("tum_fr1_rpy/groundtruth.txt").string(), "--json"});
    INFO(e.err);
    REQUIRE(e.code == 0);
    const auto j = nlohmann::json::parse(e.out);
    MESSAGE(j["loops"].size() << " loop edges, " << j["true_edges"] << " true; recall@100%P "
                              << j["recall_at_100_precision"]);
    CHECK_FALSE(j["loops"].empty());
    CHECK(j["true_edges"] == j["loops"].size());
    CHECK(j["false_positives"] == 0);
  }

  TEST_CASE("cli: loops on a sequence names each loop's frames and times; --out writes loops.txt and loops.g2o") {
    // Poses for rtabmap_loop's 84 frames (paired by order): frame k on a circle of
    // radius 5 m, one turn per 42 frames, looking along the circle, so that the g2o
    // edges have rotation and translation to check.
    const fs::path dir = fresh_dir("loops_exports");
    std::string tum = "# timestamp tx ty tz qx qy qz qw\n";
    for (int k = 0; k < 84; ++k) {
      const double a = 2.0 * 3.14159265358979 * k / 42.0;
      char row[160];
      std::snprintf(row, sizeof row, "%d %.12f %.12f 0 0 0 %.12f %.12f\n", k + 1, 5 * std::cos(a), 5 * std::sin(a),
                    std::sin(a / 2), std::cos(a / 2));
      tum += row;
    }
    write(dir / "poses.txt", tum);
    const std::string images = vmap::test::data_path("rtabmap_loop/images").string();
    const Run r = run_vmap({"loops", images, "--gt-poses", (dir / "poses.txt").string(), "--out", (dir / "out").string(),
                            "--json"});
    INFO(r.err);
    REQUIRE(r.code == 0);
    const auto j = nlohmann::json::parse(r.out);
    const auto& loops = j["loops"];
    REQUIRE(loops.size() >= 10);
    CHECK(j["files"] == nlohmann::json({"loops.txt", "loops.g2o", "pr.csv", "pr.png"}));
    for (const auto& l : loops) {
      // Frame k is images/(k+1).jpg, whose name is its time in seconds.
      const auto q = l["query"].get<std::size_t>(), m = l["match"].get<std::size_t>();
      CHECK(l["query_name"] == std::to_string(q + 1) + ".jpg");
      CHECK(l["match_name"] == std::to_string(m + 1) + ".jpg");
      CHECK(l["query_time"].get<double>() == static_cast<double>(q + 1));
      CHECK(l["match_time"].get<double>() == static_cast<double>(m + 1));
    }
    std::istringstream pairs(slurp(dir / "out" / "loops.txt"));
    std::string line;
    std::getline(pairs, line);
    CHECK(line == "# query_time match_time query_name match_name inliers");
    for (const auto& l : loops) {
      REQUIRE(std::getline(pairs, line));
      CHECK(line == std::to_string(l["query"].get<std::size_t>() + 1) + " " + std::to_string(l["match"].get<std::size_t>() + 1) +
                        " " + l["query_name"].get<std::string>() + " " + l["match_name"].get<std::string>() + " " +
                        std::to_string(l["inliers"].get<int>()));
    }
    CHECK(!std::getline(pairs, line));
    const auto poses = vmap::load_tum_poses(dir / "poses.txt");
    std::istringstream g2o(slurp(dir / "out" / "loops.g2o"));
    std::size_t edges = 0;
    std::vector<std::size_t> vertices;
    for (; std::getline(g2o, line);) {
      std::istringstream row(line);
      std::vector<std::string> t;
      for (std::string s; row >> s;) t.push_back(s);
      if (t[0] == "VERTEX_SE3:QUAT") {
        REQUIRE(t.size() == 9);
        const auto id = std::stoul(t[1]);
        vertices.push_back(id);
        CHECK(std::stod(t[2]) == doctest::Approx(poses[id].position[0]).epsilon(1e-9));
        CHECK(std::stod(t[3]) == doctest::Approx(poses[id].position[1]).epsilon(1e-9));
        continue;
      }
      REQUIRE(t[0] == "EDGE_SE3:QUAT");
      REQUIRE(t.size() == 31);
      REQUIRE(edges < loops.size());
      const auto from = std::stoul(t[1]), to = std::stoul(t[2]);
      CHECK(from == loops[edges]["query"].get<std::size_t>());
      CHECK(to == loops[edges]["match"].get<std::size_t>());
      // The pose of `to` in the frame of `from`: R_from^T (p_to - p_from), and about z
      // the angle between them (qz = sin(d/2)).
      const cv::Vec3d d = poses[from].rotation.t() * (poses[to].position - poses[from].position);
      for (std::size_t k = 0; k < 3; ++k) CHECK(std::stod(t[3 + k]) == doctest::Approx(d[static_cast<int>(k)]).epsilon(1e-6));
      const double turn = 2.0 * 3.14159265358979 * (static_cast<double>(to) - static_cast<double>(from)) / 42.0;
      CHECK(std::abs(std::stod(t[8])) == doctest::Approx(std::abs(std::sin(turn / 2))).epsilon(1e-5));
      ++edges;
    }
    CHECK(edges == loops.size());
    CHECK(std::is_sorted(vertices.begin(), vertices.end()));
    const Run text = run_vmap({"loops", images, "--out", (dir / "text").string()});
    REQUIRE(text.code == 0);
    CHECK(text.out.find(".jpg) -> frame") != std::string::npos);
    CHECK(text.out.find("wrote " + (dir / "text").string() + "/{loops.txt}") != std::string::npos);
    CHECK(slurp(dir / "text" / "loops.txt") == slurp(dir / "out" / "loops.txt"));
  }
}

/// `memory info --json` without the sizes on disk (a store and a .vmem file, or two stores
/// written in other orders, hold one memory in other bytes).
nlohmann::json without_sizes(nlohmann::json j) {
  j.erase("bytes");
  for (auto& s : j["sessions"]) s.erase("bytes");
  return j;
}

TEST_CASE("cli: a memory store is replaced only with --force, resumed only from its own input, written by one program") {
  const fs::path dir = fresh_dir("store_rules");
  const std::string mem = (dir / "m.vmdb").string();
  REQUIRE(run_vmap({"memory", "build", sample, "--memory", mem, "--end", "20"}).code == 0);
  const std::string before = slurp(mem);
  usage_error({"memory", "build", sample, "--memory", mem},
              "exists: give --resume to continue it, --session new to add a run to it, or --force to replace it");
  usage_error({"build", sample, "--memory", mem, "--end", "10"}, "exists: give --resume to continue it, --session new");
  usage_error({"build", sample, "--memory", mem, "--resume", "--force"}, "--resume and --force conflict");
  CHECK(slurp(mem) == before);
  // Another input, or the same with another stride: refused, naming both.
  const std::string other = "examples/data/tum_fr1_rpy_60/rgb";
  usage_error({"memory", "build", other, "--memory", mem, "--resume"}, "was built from '");
  usage_error({"memory", "build", sample, "--memory", mem, "--resume", "--stride", "2"}, "stride 1); this run reads");
  CHECK(slurp(mem) == before);
  // Another program writing the memory (a lock held as a writer holds it): a second
  // writer is refused with the memory named; a reader still reads it.
  {
    const int fd = ::open(mem.c_str(), O_RDWR);
    REQUIRE(fd >= 0);
    REQUIRE(::flock(fd, LOCK_EX | LOCK_NB) == 0);
    const Run second = run_vmap({"memory", "build", sample, "--memory", mem, "--resume"});
    CHECK(second.code == 7);
    CHECK(second.err.find("memory '" + mem + "' is being written by another program") != std::string::npos);
    const Run reader = run_vmap({"memory", "info", mem, "--json"});
    CHECK(reader.code == 0);
    ::close(fd);
  }
  CHECK(slurp(mem) == before);
  // --force replaces it; --resume continues it after the 20 frames.
  const Run forced = run_vmap({"memory", "build", sample, "--memory", mem, "--end", "10", "--force", "--json"});
  REQUIRE(forced.code == 0);
  CHECK(nlohmann::json::parse(forced.out)["frames"] == 10);
  const Run resumed = run_vmap({"memory", "build", sample, "--memory", mem, "--resume", "--json"});
  INFO(resumed.err);
  REQUIRE(resumed.code == 0);
  CHECK(nlohmann::json::parse(resumed.out)["frames"] == 60);
  // A refused fresh run leaves no memory behind.
  const std::string none = (dir / "none.vmdb").string();
  fails_with({"memory", "build", (dir / "missing.txt").string(), "--memory", none}, 3, "missing.txt");
  CHECK(!fs::exists(none));
}

namespace {

/// The files of `dir` a replacement builds beside a memory (".NAME.vmap-new-PID-N").
std::vector<std::string> replacement_files(const fs::path& dir) {
  std::vector<std::string> out;
  for (const auto& e : fs::directory_iterator(dir))
    if (e.path().filename().string().find(".vmap-new-") != std::string::npos) out.push_back(e.path().filename());
  return out;
}

std::size_t key_images_of(const std::string& mem) {
  const Run info = run_vmap({"memory", "info", mem, "--json"});
  REQUIRE(info.code == 0);
  return nlohmann::json::parse(info.out)["key_images"].size();
}

}  // namespace

TEST_CASE("cli: --force replaces a memory whole: a failed run, or a memory another run writes, leaves it as it was") {
  const fs::path dir = fresh_dir("store_replace");
  const std::string mem = (dir / "m.vmdb").string();
  REQUIRE(run_vmap({"memory", "build", sample, "--memory", mem, "--end", "20"}).code == 0);
  const std::size_t keys = key_images_of(mem);
  REQUIRE(keys > 1);
  const std::string before = slurp(mem);
  // No decodable frame, or no frame in the range: the run fails and the old memory stays.
  fs::create_directories(dir / "bad");
  write(dir / "bad" / "0001.jpg", "not an image");
  write(dir / "bad" / "0002.jpg", "not an image either");
  const Run bad = run_vmap({"build", (dir / "bad").string(), "--memory", mem, "--force"});
  INFO(bad.err);
  CHECK(bad.code == 1);
  fails_with({"build", sample, "--memory", mem, "--force", "--start", "5000"}, 1, "gave no frame in the requested range");
  CHECK(slurp(mem) == before);
  CHECK(key_images_of(mem) == keys);
  CHECK(replacement_files(dir).empty());

  // A memory another `vmap build` writes (a long input: the sample five times over) is
  // not replaced: that run completes with its own memory.
  std::string list;
  for (int lap = 0; lap < 5; ++lap) {
    std::ifstream in(std::string(VMAP_TEST_SOURCE_DIR) + "/" + sample);
    std::string line;
    while (std::getline(in, line)) {
      if (line.empty() || line[0] == '#') continue;
      const auto space = line.find(' ');
      list += std::to_string(std::stod(line.substr(0, space)) + 10.0 * lap) + " " + VMAP_TEST_SOURCE_DIR +
              "/examples/data/tum_fr1_rpy_60/" + line.substr(space + 1) + "\n";
    }
  }
  write(dir / "long.txt", list);
  const std::string busy = (dir / "busy.vmdb").string();
  const fs::path code = dir / "first.code";
  const std::string first = "cd " + quote(VMAP_TEST_SOURCE_DIR) + " && (" + quote(VMAP_CLI_BINARY) + " build " +
                            quote((dir / "long.txt").string()) + " --memory " + quote(busy) +
                            " --save-every 1 >/dev/null 2>" + quote((dir / "first.err").string()) + "; echo $? > " +
                            quote(code.string()) + ") &";
  REQUIRE(std::system(first.c_str()) == 0);
  const auto wait_for = [](const fs::path& p) {
    for (int i = 0; i < 1200 && !fs::exists(p); ++i) std::this_thread::sleep_for(std::chrono::milliseconds(50));
    return fs::exists(p);
  };
  REQUIRE(wait_for(busy));
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  const Run forced = run_vmap({"build", sample, "--memory", busy, "--force", "--end", "10"});
  CHECK(forced.code == 7);
  CHECK(forced.err.find("memory '" + busy + "' is being written by another program") != std::string::npos);
  REQUIRE(wait_for(code));
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  CHECK(slurp(code) == "0\n");
  const auto info = nlohmann::json::parse(run_vmap({"memory", "info", busy, "--json"}).out);
  CHECK(info["frames"] == 300);
  CHECK(replacement_files(dir).empty());

  // A FIFO as the memory written, with or without --force, or read: refused unopened.
  const fs::path fifo = dir / "fifo.vmdb";
  REQUIRE(::mkfifo(fifo.c_str(), 0600) == 0);
  for (const std::vector<std::string>& args :
       {std::vector<std::string>{"build", sample, "--memory", fifo.string(), "--force"},
        std::vector<std::string>{"build", sample, "--memory", fifo.string()},
        std::vector<std::string>{"memory", "convert", mem, fifo.string(), "--force"},
        std::vector<std::string>{"memory", "merge", mem, busy, "--out", fifo.string(), "--force"}}) {
    CAPTURE(args.front());
    fails_with(args, 2, "'" + fifo.string() + "' is not a regular file");
  }
  fails_with({"memory", "info", fifo.string()}, 2, "'" + fifo.string() + "' is not a regular file");
  fails_with({"memory", "convert", fifo.string(), (dir / "x.vmdb").string()}, 2, "is not a regular file");
  CHECK(fs::is_fifo(fifo));
}

TEST_CASE("cli: memory convert turns .vmem files of every version into stores that answer the same") {
  const fs::path dir = fresh_dir("store_convert");
  for (const char* name : {"labels_gcs.vmem", "labels_gcs_v2.vmem", "v1_five_keys.vmem"}) {
    CAPTURE(name);
    const std::string vmem = "tests/fuzz/corpus/memory/" + std::string(name);
    const std::string store = (dir / (std::string(name) + ".vmdb")).string();
    const Run c = run_vmap({"memory", "convert", vmem, store, "--json"});
    INFO(c.err);
    REQUIRE(c.code == 0);
    const Run a = run_vmap({"memory", "info", vmem, "--json"});
    const Run b = run_vmap({"memory", "info", store, "--json"});
    REQUIRE(a.code == 0);
    REQUIRE(b.code == 0);
    CHECK(without_sizes(nlohmann::json::parse(a.out)) == without_sizes(nlohmann::json::parse(b.out)));
    usage_error({"memory", "convert", vmem, store}, "exists: give --force to replace it");
    CHECK(run_vmap({"memory", "convert", vmem, store, "--force"}).code == 0);
  }
  // A .vmem is read as it is but not resumed: convert it first.
  usage_error({"memory", "build", sample, "--memory", "tests/fuzz/corpus/memory/labels_gcs.vmem", "--resume"},
              "convert it to a memory store first");
  fails_with({"memory", "convert", sample, (dir / "x.vmdb").string()}, 4, "is not a vmap memory");
  CHECK(!fs::exists(dir / "x.vmdb"));
}

TEST_CASE("cli: --session new adds a run to a memory; memory merge of two memories equals it; info lists sessions") {
  const fs::path dir = fresh_dir("sessions");
  const std::string two = (dir / "two.vmdb").string();
  REQUIRE(run_vmap({"memory", "build", sample, "--memory", two, "--end", "40"}).code == 0);
  usage_error({"memory", "build", sample, "--memory", two, "--session", "new", "--resume"},
              "--session new and --resume conflict");
  usage_error({"build", sample, "--memory", two, "--session", "new", "--force"}, "--session new and --force conflict");
  usage_error({"build", sample, "--memory", two, "--session", "again"}, "--session");
  usage_error({"build", sample, "--session", "new"}, "--session needs --memory");
  usage_error({"memory", "build", sample, "--memory", (dir / "none.vmdb").string(), "--session", "new"},
              "--session new: no memory file");
  usage_error({"memory", "build", sample, "--memory", two, "--session", "new", "--threshold", "0.5"},
              "--session new and --threshold conflict");
  const Run second = run_vmap({"build", sample, "--memory", two, "--session", "new", "--start", "20", "--json"});
  INFO(second.err);
  REQUIRE(second.code == 0);
  const auto built = nlohmann::json::parse(second.out);
  CHECK(built["memory"]["session"] == 1);
  CHECK(built["memory"]["pushed"] == 40);

  const Run info = run_vmap({"memory", "info", two, "--json"});
  REQUIRE(info.code == 0);
  auto j = nlohmann::json::parse(info.out);
  REQUIRE(j["sessions"].size() == 2);
  CHECK(j["frames"] == 80);
  CHECK(j["sessions"][0]["frames"] == 40);
  CHECK(j["sessions"][1]["frames"] == 40);
  CHECK(j["sessions"][1]["first_key"] == j["sessions"][0]["key_images"]);
  CHECK(j["sessions"][0]["input"].get<std::string>().find("rgb.txt") != std::string::npos);
  CHECK(j["sessions"][1]["bytes"].get<std::size_t>() > 0);
  // The second run revisits frames 20-39: loops from the second session into the first.
  CHECK(j["sessions"][1]["loops_across"].get<std::size_t>() >= 3);
  std::size_t across = 0;
  for (const auto& e : j["loops"]) across += e["from_session"] != e["to_session"] ? 1 : 0;
  CHECK(across == j["sessions"][1]["loops_across"]);
  const Run text = run_vmap({"memory", "info", two});
  CHECK(text.out.find("2 sessions") != std::string::npos);
  CHECK(text.out.find("  session 1: 40 frames") != std::string::npos);
  CHECK(text.out.find("(session 1, frame") != std::string::npos);

  // --resume continues the last session, whose input is checked; with every frame of it
  // already held, it says so.
  usage_error({"memory", "build", "examples/data/tum_fr1_rpy_60/rgb", "--memory", two, "--resume"}, "was built from '");
  usage_error({"memory", "build", sample, "--memory", two, "--resume"},
              "already holds every frame of its input (its last frame is 59)");
  usage_error({"build", sample, "--memory", two, "--resume"}, "already holds every frame of its input");

  // The documented reader without vmap (examples/loops_between.py, Python's sqlite3):
  // the same sessions, key images and loop edges (a ground truth of no loops here).
  {
    std::string row;
    for (int i = 0; i < 60; ++i) row += i == 0 ? "0" : " 0";
    std::string zeros;
    for (int i = 0; i < 60; ++i) zeros += row + "\n";
    write(dir / "none.txt", zeros);
    const fs::path out = dir / "between.txt";
    const std::string script = std::string(VMAP_TEST_SOURCE_DIR) + "/examples/loops_between.py";
    REQUIRE(std::system(("python3 " + quote(script) + " " + quote(two) + " " + quote((dir / "none.txt").string()) +
                         " 40 > " + quote(out.string()))
                            .c_str()) == 0);
    const std::string line = slurp(out);
    INFO(line);
    CHECK(line.find("2 sessions, " + std::to_string(j["key_images"].size()) + " key images, " +
                    std::to_string(j["loops"].size()) + " loop edges (" + std::to_string(across) + " across sessions)") !=
          std::string::npos);
  }

  // Two memories built apart and merged: the same memory.
  const std::string a = (dir / "a.vmdb").string(), b = (dir / "b.vmdb").string(), c = (dir / "c.vmdb").string();
  REQUIRE(run_vmap({"memory", "build", sample, "--memory", a, "--end", "40"}).code == 0);
  REQUIRE(run_vmap({"memory", "build", sample, "--memory", b, "--start", "20"}).code == 0);
  const Run merged = run_vmap({"memory", "merge", a, b, "--out", c, "--json"});
  INFO(merged.err);
  REQUIRE(merged.code == 0);
  CHECK(nlohmann::json::parse(merged.out)["sessions"] == 2);
  const auto k = nlohmann::json::parse(run_vmap({"memory", "info", c, "--json"}).out);
  CHECK(without_sizes(k) == without_sizes(j));
  CHECK(replacement_files(dir).empty());
  usage_error({"memory", "merge", a, b, "--out", c}, "exists: give --force to replace it");
  // A memory merged with itself (also under another name) would repeat its runs.
  fs::create_symlink(fs::absolute(a), dir / "a_link.vmdb");
  usage_error({"memory", "merge", a, (dir / "a_link.vmdb").string(), "--out", (dir / "self.vmdb").string()},
              "A and B are the same memory ('" + a + "')");
  CHECK(!fs::exists(dir / "self.vmdb"));
  // Other options: refused, naming both, and nothing written.
  const std::string d = (dir / "d.vmdb").string();
  REQUIRE(run_vmap({"memory", "build", sample, "--memory", d, "--end", "10", "--threshold", "0.5"}).code == 0);
  fails_with({"memory", "merge", a, d, "--out", (dir / "e.vmdb").string()}, 6,
             "cannot merge memory '" + d + "' into memory '" + a + "'");
  CHECK(!fs::exists(dir / "e.vmdb"));
}

TEST_CASE("cli: a new memory whose run fails after committing key images (a full disk) is kept and resumes") {
  const fs::path dir = fresh_dir("store_full");
  const std::string mem = (dir / "m.vmdb").string();
  // bash's file size limit stands in for a full disk: writes past 1000 KiB fail (EFBIG,
  // with SIGXFSZ ignored) after the first syncs were committed.
  const std::string inner = "trap '' XFSZ; ulimit -f 1000; exec " + quote(VMAP_CLI_BINARY) + " build " + quote(sample) +
                            " --memory " + quote(mem) + " >/dev/null 2>" + quote((dir / "err.txt").string());
  const std::string cmd = "cd " + quote(VMAP_TEST_SOURCE_DIR) + " && bash -c " + quote(inner);
  const int status = std::system(cmd.c_str());
  CHECK(WEXITSTATUS(status) == 8);
  const std::string err = slurp(dir / "err.txt");
  INFO(err);
  CHECK(err.find("the memory '" + mem + "' keeps the ") != std::string::npos);
  const std::size_t kept = key_images_of(mem);
  CHECK(kept > 0);
  // With the disk back, --resume goes on to the memory of an uninterrupted run.
  const Run resumed = run_vmap({"build", sample, "--memory", mem, "--resume"});
  INFO(resumed.err);
  CHECK(resumed.code == 0);
  const std::string whole = (dir / "whole.vmdb").string();
  REQUIRE(run_vmap({"build", sample, "--memory", whole}).code == 0);
  CHECK(key_images_of(mem) == key_images_of(whole));
  CHECK(key_images_of(mem) > kept);
}

TEST_CASE("cli: a memory store is read without vmap, by sqlite3 and by Python's sqlite3 module") {
  const auto& [file, built] = sample_memory();
  const fs::path out = work_dir() / "sqlite_read.txt";
  // The documented queries (examples/memory.md, "The memory store").
  const std::string sql = "SELECT id, frame_index, name, timestamp FROM key_images ORDER BY id LIMIT 3;";
  REQUIRE(std::system(("sqlite3 -readonly " + quote(file.string()) + " " + quote(sql) + " > " + quote(out.string())).c_str()) == 0);
  const std::string rows = slurp(out);
  CHECK(rows.find("0|0|1305031229.528748.jpg|1305031229.52875") == 0);
  const std::string py =
      "import sqlite3, sys\n"
      "db = sqlite3.connect('file:' + sys.argv[1] + '?mode=ro', uri=True)\n"
      "keys = db.execute('SELECT count(*) FROM key_images').fetchone()[0]\n"
      "loops = db.execute('SELECT count(*) FROM loops WHERE confidence >= 0.5').fetchone()[0]\n"
      "print(keys, loops)\n";
  write(work_dir() / "read_memory.py", py);
  REQUIRE(std::system(("python3 " + quote((work_dir() / "read_memory.py").string()) + " " + quote(file.string()) + " > " +
                       quote(out.string()))
                          .c_str()) == 0);
  CHECK(slurp(out) == std::to_string(built["key_images"].get<std::size_t>()) + " " +
                          std::to_string(built["memory"]["loops"].get<std::size_t>()) + "\n");
}

TEST_CASE("cli: a memory build killed (SIGKILL) at any moment resumes to the memory of an uninterrupted run") {
  const fs::path dir = fresh_dir("store_kill");
  const std::string ref = (dir / "ref.vmdb").string();
  REQUIRE(run_vmap({"memory", "build", sample, "--memory", ref, "--images", "jpeg"}).code == 0);
  const auto whole = nlohmann::json::parse(run_vmap({"memory", "info", ref, "--json"}).out);
  REQUIRE(whole["key_images"].size() >= 12);
  // The sample takes about a second to build here: kills from the store's creation to
  // near the end.
  for (const char* delay : {"0.05", "0.2", "0.35", "0.5", "0.7", "0.9"}) {
    CAPTURE(delay);
    const std::string mem = (dir / "killed.vmdb").string();
    for (const char* suffix : {"", "-wal", "-shm"}) fs::remove(mem + suffix);
    const std::string cmd = "cd " + quote(VMAP_TEST_SOURCE_DIR) + " && timeout -s KILL " + delay + " " +
                            quote(VMAP_CLI_BINARY) + " memory build " + quote(sample) + " --memory " + quote(mem) +
                            " --images jpeg >/dev/null 2>&1";
    (void)std::system(cmd.c_str());
    // What the kill left: nothing, a store without a sync, or a memory to resume.
    if (!fs::exists(mem) || run_vmap({"memory", "info", mem}).code != 0) {
      REQUIRE(run_vmap({"memory", "build", sample, "--memory", mem, "--images", "jpeg", "--force"}).code == 0);
    } else {
      const Run resumed = run_vmap({"memory", "build", sample, "--memory", mem, "--resume"});
      INFO(resumed.err);
      // Killed after the last frame was written: nothing left to read (a usage error).
      CHECK((resumed.code == 0 || resumed.err.find("already holds every frame") != std::string::npos));
    }
    const auto got = nlohmann::json::parse(run_vmap({"memory", "info", mem, "--json"}).out);
    CHECK(got["key_images"] == whole["key_images"]);
    CHECK(got["loops"] == whole["loops"]);
    CHECK(got["frames"] == whole["frames"]);
  }
}

namespace {

/// The angle of the rotation R_a^T R_b in degrees, stable near 0 (from |R_a - R_b|_F =
/// 2 sqrt(2) sin(angle / 2)).
double rotation_between_deg(const cv::Matx33d& a, const cv::Matx33d& b) {
  const double s = std::min(1.0, cv::norm(a - b) / (2.0 * std::sqrt(2.0)));
  return 2.0 * std::asin(s) * 180.0 / CV_PI;
}

cv::Matx33d rotation_of(const nlohmann::json& nine) {
  const auto v = nine.get<std::vector<double>>();
  REQUIRE(v.size() == 9);
  return cv::Matx33d(v.data());
}

}  // namespace

TEST_CASE("cli: a memory keeps the policy stack it was built with (--features, --camera); every reader uses it") {
  const fs::path dir = fresh_dir("stack");
  const std::string akaze = (dir / "akaze.vmdb").string();
  const Run b = run_vmap({"build", sample, "--memory", akaze, "--features", "akaze", "--end", "30", "--vocabulary-after",
                          "5", "--json"});
  INFO(b.err);
  REQUIRE(b.code == 0);
  const auto built = nlohmann::json::parse(b.out);
  CHECK(built["memory"]["stack"]["features"] == "akaze");
  CHECK(built["memory"]["stack"]["camera"].is_null());
  const Run i = run_vmap({"memory", "info", akaze, "--json"});
  REQUIRE(i.code == 0);
  const auto info = nlohmann::json::parse(i.out);
  CHECK(info["stack"]["features"] == "akaze");
  CHECK(info["stack"]["estimator"] == "magsac");
  CHECK(info["key_images"].size() == built["key_images"].get<std::size_t>());
  CHECK(run_vmap({"memory", "info", akaze}).out.find("(akaze, magsac, raw pixels)") != std::string::npos);
  // The first key image's own frame is found at that key image, by A-KAZE's matches (an
  // ORB reader would refuse the memory's recorded descriptor); without a camera no pose.
  const Run l = run_vmap({"localize", "--memory", akaze, frame_a, "--json"});
  INFO(l.err);
  REQUIRE(l.code == 0);
  const auto q = nlohmann::json::parse(l.out)["queries"][0];
  CHECK(q["localized"] == true);
  CHECK(q["key"] == 0);
  CHECK(q["relative_pose"].is_null());
  // A continued memory keeps its stack: the stack's options conflict, and a resumed run
  // extracts A-KAZE features again.
  usage_error({"build", sample, "--memory", akaze, "--resume", "--features", "orb"}, "--resume and --features conflict");
  usage_error({"memory", "build", sample, "--memory", akaze, "--session", "new", "--camera",
               "examples/data/tum_fr1_camera.yaml"},
              "--session new and --camera conflict");
  const Run r = run_vmap({"memory", "build", sample, "--memory", akaze, "--resume", "--end", "40", "--json"});
  INFO(r.err);
  REQUIRE(r.code == 0);
  const auto resumed = nlohmann::json::parse(r.out);
  CHECK(resumed["memory"]["stack"]["features"] == "akaze");
  CHECK(resumed["frames"] == 40);
  // Memories of two stacks are not merged.
  const std::string orb = (dir / "orb.vmdb").string();
  REQUIRE(run_vmap({"memory", "build", sample, "--memory", orb, "--end", "20"}).code == 0);
  const Run m = run_vmap({"memory", "merge", orb, akaze, "--out", (dir / "merged.vmdb").string()});
  CHECK(m.code == 6);
  CHECK(m.err.find("cannot merge memory '" + akaze + "' (akaze, magsac, raw pixels) into memory '" + orb +
                   "' (orb 1000, magsac, raw pixels): they were built with different policies") != std::string::npos);
  CHECK(!fs::exists(dir / "merged.vmdb"));
  // The camera is kept in the memory (its file is not read again) and gives each accepted
  // query its pose relative to the key image.
  fs::copy_file(fs::path(VMAP_TEST_SOURCE_DIR) / "examples/data/tum_fr1_camera.yaml", dir / "camera.yaml");
  const std::string cam = (dir / "camera.vmdb").string();
  const Run c = run_vmap({"memory", "build", sample, "--memory", cam, "--camera", (dir / "camera.yaml").string(),
                          "--end", "30", "--json"});
  INFO(c.err);
  REQUIRE(c.code == 0);
  const auto camera = nlohmann::json::parse(c.out)["memory"]["stack"]["camera"];
  CHECK(camera["fx"] == 517.3);
  CHECK(camera["cy"] == 255.3);
  CHECK(camera["distortion"].size() == 5);
  CHECK(camera["width"] == 640);
  fs::remove(dir / "camera.yaml");
  // Frame 19, which turns about 5 degrees from its key image (frame 16).
  const std::string turned = "examples/data/tum_fr1_rpy_60/rgb/1305031230.165771.jpg";
  const Run p = run_vmap({"localize", "--memory", cam, turned, "--json"});
  INFO(p.err);
  REQUIRE(p.code == 0);
  const auto pq = nlohmann::json::parse(p.out)["queries"][0];
  REQUIRE(pq["localized"] == true);
  REQUIRE(pq["relative_pose"].is_object());
  const cv::Matx33d R = rotation_of(pq["relative_pose"]["rotation"]);
  CHECK(cv::norm(R.t() * R - cv::Matx33d::eye()) < 1e-9);
  CHECK(cv::determinant(R) == doctest::Approx(1.0).epsilon(1e-9));
  const auto t = pq["relative_pose"]["translation"].get<std::vector<double>>();
  CHECK(std::hypot(t[0], t[1], t[2]) == doctest::Approx(1.0).epsilon(1e-9));
  CHECK(pq["relative_pose"]["points_in_front"].get<int>() >= 1);
  CHECK(pq["relative_pose"]["rotation_degrees"].get<double>() ==
        doctest::Approx(rotation_between_deg(R, cv::Matx33d::eye())).epsilon(1e-6));
  CHECK(run_vmap({"localize", "--memory", cam, turned}).out.find("  relative to the key image: rotation ") !=
        std::string::npos);
}

TEST_SUITE("data") {
  TEST_CASE("cli: a memory with --camera gives a localized query's rotation from its key image as motion capture does") {
    // Even frames 0-198 of tum_fr1_rpy mapped, 20 odd frames localized; the ground truth
    // (camera to world, R_w) gives the motion from the query's camera to the key image's
    // as R_wk^T R_wq. Measured: 17 of 20 with a pose, errors 0.0-1.8 degrees (the other
    // three turn without parallax and get none).
    const fs::path dir = fresh_dir("camera_pose");
    const std::string seq = vmap::test::data_path("tum_fr1_rpy/rgb.txt").string();
    const std::string mem = (dir / "m.vmdb").string();
    const Run b = run_vmap({"build", seq, "--memory", mem, "--camera", "examples/data/tum_fr1_camera.yaml", "--end", "200",
                            "--stride", "2"});
    INFO(b.err);
    REQUIRE(b.code == 0);
    auto src = vmap::FrameSource::open(seq, {.grey = true});
    const auto paths = src.paths();
    std::vector<std::string> args{"localize", "--memory", mem, "--json"};
    for (std::size_t k = 1; k < 200; k += 10) args.push_back(paths.at(k).string());
    const Run l = run_vmap(args);
    INFO(l.err);
    REQUIRE(l.code == 0);
    const auto gt = vmap::load_camera_poses(vmap::test::data_path("tum_fr1_rpy/groundtruth.txt"));
    const auto rotation_at = [&](const std::string& name) {
      const double time = std::stod(fs::path(name).stem().string());
      return vmap::poses_for_frames(gt, {time}, "groundtruth.txt", 0.05, false).front().rotation;
    };
    std::vector<double> errors;
    const auto answers = nlohmann::json::parse(l.out);
    for (const auto& q : answers["queries"]) {
      if (!q["localized"].get<bool>() || q["relative_pose"].is_null()) continue;
      const cv::Matx33d truth = rotation_at(q["matches"][0]["name"].get<std::string>()).t() *
                                rotation_at(q["image"].get<std::string>());
      errors.push_back(rotation_between_deg(rotation_of(q["relative_pose"]["rotation"]), truth));
    }
    MESSAGE(errors.size() << " relative poses");
    REQUIRE(errors.size() >= 12);
    std::sort(errors.begin(), errors.end());
    CHECK(errors[errors.size() / 2] < 1.0);
    CHECK(errors.back() < 3.0);
  }

  TEST_CASE("cli: a memory of XFeat* records its models; localize and --resume use them without --model") {
    const fs::path dir = fresh_dir("xfeat_stack");
    const std::string mem = (dir / "x.vmdb").string();
    const std::string model = vmap::test::model_path("xfeat_anysize.onnx").string();
    const std::string fine = vmap::test::model_path("xfeat_fine.onnx").string();
    const Run b = run_vmap({"build", sample, "--memory", mem, "--features", "xfeat-star", "--model", model,
                            "--refine-model", fine, "--threshold", "0.1", "--vocabulary-after", "3", "--end", "12",
                            "--json"});
    INFO(b.err);
    REQUIRE(b.code == 0);
    const auto stack = nlohmann::json::parse(b.out)["memory"]["stack"];
    CHECK(stack["features"] == "xfeat-star");
    CHECK(stack["model"] == fs::weakly_canonical(model).string());
    CHECK(stack["refine_model"] == fs::weakly_canonical(fine).string());
    const Run l = run_vmap({"localize", "--memory", mem, frame_b, "--json"});
    INFO(l.err);
    REQUIRE(l.code == 0);
    const auto j = nlohmann::json::parse(l.out);
    CHECK(j["stack"] == stack);
    CHECK(j["queries"][0]["verified_candidates"].get<std::size_t>() >= 1);
    // The matches the refinement kept of the dense grid's coarse ones, which the decision
    // weighs the inliers against.
    CHECK(j["queries"][0]["evidence"]["matches"].get<int>() > 300);
    CHECK(j["queries"][0]["evidence"]["inliers"].get<int>() <= j["queries"][0]["evidence"]["matches"].get<int>());
    const Run r = run_vmap({"build", sample, "--memory", mem, "--resume", "--end", "16", "--json"});
    INFO(r.err);
    REQUIRE(r.code == 0);
    CHECK(nlohmann::json::parse(r.out)["memory"]["last_frame_index"] == 15);
  }
}

TEST_CASE("cli: robots of a fleet's memory on PostgreSQL build with --robot, find loops between them, move to files and back") {
  auto* server = vmap::test::test_server();
  if (!server) return;
  const std::string uri = server->uri("cli_fleet");
  const fs::path dir = fresh_dir("fleet");
  // One vocabulary for every robot: bags of words of two vocabularies do not compare.
  const std::string voc = (dir / "voc.bin").string();
  REQUIRE(run_vmap({"vocabulary", sample, "--words", "512", "--depth", "3", "--out", voc}).code == 0);
  const std::string file = (dir / "a.vmdb").string();
  REQUIRE(run_vmap({"memory", "build", sample, "--memory", file, "--vocabulary", voc}).code == 0);
  const Run a = run_vmap({"memory", "build", sample, "--memory", uri, "--robot", "a", "--vocabulary", voc, "--json"});
  INFO(a.err);
  REQUIRE(a.code == 0);
  const auto aj = nlohmann::json::parse(a.out);
  CHECK(aj["memory"]["robot"] == "a");
  CHECK(aj["memory"]["file"] == uri);
  CHECK(aj["memory"]["bytes"].is_null());
  // Robot a's memory is the file's, key image for key image and loop for loop.
  const auto in_file = nlohmann::json::parse(run_vmap({"memory", "info", file, "--json"}).out);
  const auto on_server = nlohmann::json::parse(run_vmap({"memory", "info", uri, "--robot", "a", "--json"}).out);
  CHECK(on_server["key_images"] == in_file["key_images"]);
  CHECK(on_server["loops"] == in_file["loops"]);
  CHECK(on_server["frames"] == in_file["frames"]);
  CHECK(on_server["robot"] == "a");
  // Robot b maps the same place: its key images are found among robot a's.
  const Run b = run_vmap({"memory", "build", sample, "--memory", uri, "--robot", "b", "--vocabulary", voc});
  INFO(b.err);
  REQUIRE(b.code == 0);
  CHECK(b.out.find("robot 'b'") != std::string::npos);
  const auto fleet = nlohmann::json::parse(run_vmap({"memory", "info", uri, "--json"}).out);
  REQUIRE(fleet["robots"].size() == 2);
  CHECK(fleet["robots"][0]["robot"] == "a");
  CHECK(fleet["robots"][0]["key_images"] == in_file["key_images"].size());
  CHECK(fleet["robots"][1]["robot"] == "b");
  CHECK(fleet["robots"][1]["fleet_loops"].get<std::size_t>() * 2 >= fleet["robots"][1]["key_images"].get<std::size_t>());
  REQUIRE(!fleet["fleet_loops"].empty());
  for (const auto& l : fleet["fleet_loops"]) {
    CHECK(l["from_robot"] == "b");
    CHECK(l["to_robot"] == "a");
  }
  const Run text = run_vmap({"memory", "info", uri});
  CHECK(text.out.find("2 robots") != std::string::npos);
  // Moved into a file and back into the fleet: equal record for record.
  const std::string back = (dir / "back.vmdb").string();
  REQUIRE(run_vmap({"memory", "convert", uri, back, "--robot", "a"}).code == 0);
  const auto back_info = nlohmann::json::parse(run_vmap({"memory", "info", back, "--json"}).out);
  CHECK(back_info["key_images"] == in_file["key_images"]);
  CHECK(back_info["loops"] == in_file["loops"]);
  // (convert copies the records; the note of the input a session was built from stays behind)
  REQUIRE(back_info["sessions"].size() == in_file["sessions"].size());
  for (const char* field : {"first_key", "frames", "key_images", "loops_within", "loops_across", "bytes"})
    CHECK(back_info["sessions"][0][field] == in_file["sessions"][0][field]);
  REQUIRE(run_vmap({"memory", "convert", file, uri, "--robot", "a2"}).code == 0);
  const auto a2 = nlohmann::json::parse(run_vmap({"memory", "info", uri, "--robot", "a2", "--json"}).out);
  CHECK(a2["key_images"] == in_file["key_images"]);
  CHECK(a2["loops"] == in_file["loops"]);
  // Merged files written into the fleet as one robot.
  const Run merged = run_vmap({"memory", "merge", file, back, "--out", uri, "--robot", "ab", "--json"});
  INFO(merged.err);
  REQUIRE(merged.code == 0);
  CHECK(nlohmann::json::parse(merged.out)["sessions"] == 2);
  // Localized among every robot, or in one.
  const Run where = run_vmap({"localize", "--memory", uri, frame_a, "--json"});
  INFO(where.err);
  REQUIRE(where.code == 0);
  const auto wj = nlohmann::json::parse(where.out);
  CHECK(wj["queries"][0]["localized"] == true);
  CHECK(wj["robots"].size() == 4);
  const Run in_b = run_vmap({"localize", "--memory", uri, "--robot", "b", frame_a, "--json"});
  CHECK(nlohmann::json::parse(in_b.out)["queries"][0]["localized"] == true);
  // Continued: --resume, --session new; an existing robot is never replaced.
  const Run again = run_vmap({"memory", "build", sample, "--memory", uri, "--robot", "a"});
  CHECK(again.code == 2);
  CHECK(again.err.find("robot 'a' of memory '" + uri + "' exists") != std::string::npos);
  const Run force = run_vmap({"memory", "build", sample, "--memory", uri, "--robot", "a", "--force"});
  CHECK(force.code == 2);
  CHECK(force.err.find("a fleet's robot is not replaced") != std::string::npos);
  const Run session = run_vmap({"memory", "build", sample, "--memory", uri, "--robot", "a", "--session", "new", "--json"});
  INFO(session.err);
  CHECK(session.code == 0);
  CHECK(nlohmann::json::parse(run_vmap({"memory", "info", uri, "--robot", "a", "--json"}).out)["sessions"].size() == 2);
  // Usage: no robot where one writes; --robot with a file; a server that cannot be reached.
  const Run no_robot = run_vmap({"memory", "build", sample, "--memory", uri});
  CHECK(no_robot.code == 2);
  CHECK(no_robot.err.find("give --robot NAME") != std::string::npos);
  CHECK(run_vmap({"memory", "build", sample, "--memory", (dir / "c.vmdb").string(), "--robot", "c"}).code == 2);
  const Run away = run_vmap({"memory", "info", "postgresql://fleet:s3cret@127.0.0.1:1/vmap?connect_timeout=2", "--robot", "a"});
  CHECK(away.code == 9);
  CHECK(away.err.find("s3cret") == std::string::npos);
  const Run missing = run_vmap({"memory", "info", uri, "--robot", "zed"});
  CHECK(missing.code == 3);
  CHECK(missing.err.find("its robots: a, b, a2, ab") != std::string::npos);
}

TEST_CASE("cli: a robot of a fleet's memory killed (SIGKILL) at any moment resumes to the memory of an uninterrupted run") {
  auto* server = vmap::test::test_server();
  if (!server) return;
  const std::string uri = server->uri("cli_fleet_kill");
  REQUIRE(run_vmap({"memory", "build", sample, "--memory", uri, "--robot", "ref", "--images", "jpeg"}).code == 0);
  const auto whole = nlohmann::json::parse(run_vmap({"memory", "info", uri, "--robot", "ref", "--json"}).out);
  REQUIRE(whole["key_images"].size() >= 12);
  int trial = 0;
  for (const char* delay : {"0.05", "0.2", "0.35", "0.5", "0.7", "0.9"}) {
    CAPTURE(delay);
    const std::string robot = "killed" + std::to_string(trial++);
    const std::string cmd = "cd " + quote(VMAP_TEST_SOURCE_DIR) + " && timeout -s KILL " + delay + " " +
                            quote(VMAP_CLI_BINARY) + " memory build " + quote(sample) + " --memory " + quote(uri) +
                            " --robot " + robot + " --images jpeg >/dev/null 2>&1";
    (void)std::system(cmd.c_str());
    // What the kill left: no robot, a robot without a sync (started again with --force), or
    // a memory to resume; the server freed the killed writer's lock with its connection.
    const Run resumed = run_vmap({"memory", "build", sample, "--memory", uri, "--robot", robot, "--resume"});
    if (resumed.code != 0 && resumed.err.find("already holds every frame") == std::string::npos) {
      INFO(resumed.err);
      const Run again = run_vmap({"memory", "build", sample, "--memory", uri, "--robot", robot, "--images", "jpeg", "--force"});
      INFO(again.err);
      REQUIRE(again.code == 0);
    }
    const auto got = nlohmann::json::parse(run_vmap({"memory", "info", uri, "--robot", robot, "--json"}).out);
    CHECK(got["key_images"] == whole["key_images"]);
    CHECK(got["loops"] == whole["loops"]);
    CHECK(got["frames"] == whole["frames"]);
  }
}

namespace {

/// run_vmap killed after `seconds` (exit 137): for inputs that must be refused at once,
/// so that a run that waits on one fails the test instead of hanging it.
Run run_vmap_within(int seconds, const std::vector<std::string>& args) {
  return run_vmap_prefixed("timeout -s KILL " + std::to_string(seconds), args);
}

/// Runs `vmap ARGS...` as run_vmap does, with `env` ("NAME=value ...") set for it.
Run run_vmap_with(const std::string& env, const std::vector<std::string>& args) {
  return run_vmap_prefixed("env " + env, args);
}

/// A process id that is no process's: a child that has ended.
std::string dead_pid() {
  const pid_t child = ::fork();
  REQUIRE(child >= 0);
  if (child == 0) ::_exit(0);
  REQUIRE(::waitpid(child, nullptr, 0) == child);
  return std::to_string(child);
}

}  // namespace

TEST_CASE("cli: --force replaces only memories: an SQLite database or a rosbag2 file is never one") {
  const fs::path dir = fresh_dir("foreign_sqlite");
  const std::string a = (dir / "a.vmdb").string(), b = (dir / "b.vmdb").string();
  REQUIRE(run_vmap({"build", sample, "--memory", a, "--end", "20"}).code == 0);
  REQUIRE(run_vmap({"build", sample, "--memory", b, "--start", "20"}).code == 0);
  const std::string user = (dir / "p.db").string();
  REQUIRE(std::system(("sqlite3 " + quote(user) + " \"create table t(x); insert into t values('mine')\"").c_str()) == 0);
  const std::string bag = (dir / "bag.db3").string();
  REQUIRE(std::system(("sqlite3 " + quote(bag) + " \"pragma journal_mode=wal; create table messages(data blob)\" >/dev/null")
                          .c_str()) == 0);
  for (const std::string& other : {user, bag}) {
    CAPTURE(other);
    const std::string before = slurp(other);
    for (const std::vector<std::string>& args :
         {std::vector<std::string>{"build", sample, "--end", "8", "--memory", other, "--force"},
          std::vector<std::string>{"memory", "convert", a, other, "--force"},
          std::vector<std::string>{"memory", "merge", a, b, "--out", other, "--force"},
          std::vector<std::string>{"build", sample, "--end", "8", "--memory", other},
          std::vector<std::string>{"memory", "convert", a, other}}) {
      CAPTURE(args[1]);
      const Run r = fails_with(args, 2, "'" + other + "' exists and is not a vmap memory; refusing to replace it");
      // Not called a memory, and --force not suggested for it.
      CHECK(r.err.find("the memory") == std::string::npos);
      CHECK(r.err.find("give --force") == std::string::npos);
    }
    CHECK(slurp(other) == before);
  }
  const Run rows = run_vmap({"memory", "info", user});
  CHECK(rows.code == 4);
  CHECK(rows.err.find("is not a vmap memory") != std::string::npos);
}

TEST_CASE("cli: a new memory store appears whole, and the files of runs killed before are removed by the next") {
  const fs::path dir = fresh_dir("whole_new");
  const std::string a = (dir / "a.vmdb").string();
  REQUIRE(run_vmap({"build", sample, "--memory", a, "--end", "30"}).code == 0);
  const auto whole = nlohmann::json::parse(run_vmap({"memory", "info", a, "--json"}).out);
  // The leftovers of a killed run (a process that has ended) beside the memory.
  const std::string pid = dead_pid();
  for (const std::string suffix : {"-0", "-0-wal", "-0-shm", "-1", "-1-journal"})
    write(dir / (".m.vmdb.vmap-new-" + pid + suffix), "left by a killed run");
  const std::string m = (dir / "m.vmdb").string();
  REQUIRE(run_vmap({"memory", "convert", a, m}).code == 0);
  CHECK(replacement_files(dir).empty());
  const auto converted = nlohmann::json::parse(run_vmap({"memory", "info", m, "--json"}).out);
  CHECK(converted["key_images"] == whole["key_images"]);
  write(dir / (".m.vmdb.vmap-new-" + pid + "-2"), "left by a killed run");
  REQUIRE(run_vmap({"build", sample, "--memory", m, "--end", "10", "--force"}).code == 0);
  CHECK(replacement_files(dir).empty());

  // Killed at each of its flushes to disk (SQLite's fdatasync, vmap's fsync), a convert
  // to a new output leaves no file there or the whole memory, never an empty or broken
  // one (strace injects the kill).
  if (std::system("strace -f -o /dev/null true >/dev/null 2>&1") != 0) {
    MESSAGE("skipped: strace cannot trace here (the kills at each flush)");
    return;
  }
  int absent = 0, complete = 0;
  for (const std::string call : {"fdatasync", "fsync"}) {
    const std::string count_cmd = "cd " + quote(VMAP_TEST_SOURCE_DIR) + " && strace -f -c -e trace=" + call + " " +
                                  quote(VMAP_CLI_BINARY) + " memory convert " + quote(a) + " " +
                                  quote((dir / ("count-" + call + ".vmdb")).string()) +
                                  " 2>&1 >/dev/null | awk '$NF == \"" + call + "\" { print $4 }' > " +
                                  quote((dir / "calls").string());
    REQUIRE(std::system(count_cmd.c_str()) == 0);
    const int calls = std::atoi(slurp(dir / "calls").c_str());
    CAPTURE(call);
    REQUIRE(calls >= 1);
    for (int n = 1; n <= std::min(calls, 12); ++n) {
      CAPTURE(n);
      const fs::path trial = dir / (call + std::to_string(n));
      fs::create_directories(trial);
      const std::string out = (trial / "new.vmdb").string();
      const std::string cmd = "cd " + quote(VMAP_TEST_SOURCE_DIR) + " && strace -f -o /dev/null -e trace=" + call +
                              " -e inject=" + call + ":signal=KILL:when=" + std::to_string(n) + " " +
                              quote(VMAP_CLI_BINARY) + " memory convert " + quote(a) + " " + quote(out) + " >/dev/null 2>&1";
      (void)std::system(cmd.c_str());
      if (!fs::exists(out)) {
        ++absent;
        continue;
      }
      const Run info = run_vmap({"memory", "info", out, "--json"});
      INFO(info.err);
      REQUIRE(info.code == 0);
      CHECK(nlohmann::json::parse(info.out)["key_images"] == whole["key_images"]);
      ++complete;
    }
  }
  CHECK(absent > 0);
  CHECK(absent + complete > 2);
}

TEST_CASE("cli: a password of a fleet's URI is never printed, in --json's options nor anywhere else") {
  auto* server = vmap::test::test_server();
  if (!server) return;
  const std::string plain = server->uri("cli_secret");
  // The test server trusts loopback: the password is given and never checked.
  const std::string uri = "postgresql://vmap:pass%2Fword@" + plain.substr(plain.find('@') + 1);
  const std::string secret = "pass";
  const fs::path dir = fresh_dir("secret");
  const auto no_secret = [&](const Run& r) {
    INFO(r.err);
    CHECK(r.code == 0);
    CHECK(r.out.find(secret) == std::string::npos);
    CHECK(r.err.find(secret) == std::string::npos);
  };
  const Run build = run_vmap({"build", sample, "--end", "20", "--memory", uri, "--robot", "x", "--json"});
  no_secret(build);
  const auto bj = nlohmann::json::parse(build.out);
  CHECK(bj["options"]["memory"] == "postgresql://vmap@" + plain.substr(plain.find('@') + 1));
  no_secret(run_vmap({"loops", "--memory", uri, "--robot", "x", "--json"}));
  no_secret(run_vmap({"memory", "localize", uri, frame_a, "--robot", "x", "--json"}));
  no_secret(run_vmap({"localize", "--memory", uri, "--robot", "x", frame_a, "--json"}));
  no_secret(run_vmap({"localize", "--memory", uri, frame_a, "--json"}));
  no_secret(run_vmap({"memory", "export", uri, "--robot", "x", "--out", (dir / "export").string(), "--json"}));
  no_secret(run_vmap({"memory", "info", uri, "--robot", "x", "--json"}));
  no_secret(run_vmap({"memory", "info", uri, "--json"}));
  // Unescaped, a password holding '/', '?' or '@' cannot be parsed: refused, not shown.
  for (const std::string bad : {"postgresql://vmap:pa/ss@127.0.0.1:1/db", "postgresql://vmap:pa?ss@127.0.0.1:1/db"}) {
    const Run r = run_vmap_with("PGCONNECT_TIMEOUT=2", {"memory", "info", bad, "--robot", "x", "--json"});
    CHECK(r.code != 0);
    CHECK(r.out.find("ss") == std::string::npos);
    CHECK(r.err.find("pa/ss") == std::string::npos);
    CHECK(r.err.find("pa?ss") == std::string::npos);
  }
}

TEST_CASE("cli: a fleet's server that stops answering ends a command with exit 9 within the timeouts") {
  auto* server = vmap::test::test_server();
  if (!server) return;
  const std::string uri = server->uri("cli_hung");
  REQUIRE(run_vmap({"build", sample, "--end", "20", "--memory", uri, "--robot", "a"}).code == 0);
  server->pause();
  struct Resume {
    vmap::test::TestPostgres* server;
    ~Resume() { server->resume(); }
  } resume{server};
  const auto t0 = std::chrono::steady_clock::now();
  const Run hung = run_vmap_with("VMAP_PG_QUERY_TIMEOUT=2 PGCONNECT_TIMEOUT=2", {"memory", "info", uri, "--robot", "a"});
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  INFO(hung.err);
  CHECK(hung.code == 9);
  CHECK(hung.err.find("try again when it is back") != std::string::npos);
  CHECK(seconds < 15.0);
  const Run bad = run_vmap_with("VMAP_PG_QUERY_TIMEOUT=soon", {"memory", "info", uri, "--robot", "a"});
  CHECK(bad.code == 1);
  CHECK(bad.err.find("VMAP_PG_QUERY_TIMEOUT: expected a number of seconds") != std::string::npos);
}

TEST_CASE("cli: an output folder that cannot be written exits 8; an output that is its input exits 2") {
  const fs::path dir = fresh_dir("exit_codes");
  // /proc refuses new files and folders to everyone, root included.
  fails_with({"build", sample, "--end", "8", "--out", "/proc/vmap-test-out"}, 8, "/proc/vmap-test-out");
  fails_with({"build", sample, "--end", "8", "--memory", "/proc/vmap-test/m.vmdb"}, 8, "/proc/vmap-test");
  const std::string m = (dir / "m.vmdb").string();
  REQUIRE(run_vmap({"build", sample, "--memory", m, "--end", "10"}).code == 0);
  fails_with({"memory", "export", m, "--out", "/proc/vmap-test-export"}, 8, "/proc/vmap-test-export");
  fails_with({"memory", "convert", m, m, "--force"}, 2, "is also an input");
  fails_with({"build", sample, "--memory", sample, "--force"}, 2, "is also an input");
  fails_with({"vocabulary", sample, "--out", sample, "--words", "8", "--depth", "1"}, 2, "is also an input");
}

TEST_CASE("cli: a new robot's name that begins or ends with a space is refused") {
  auto* server = vmap::test::test_server();
  if (!server) return;
  const std::string uri = server->uri("cli_names");
  fails_with({"build", sample, "--end", "8", "--memory", uri, "--robot", "r1 "}, 1, "begins or ends with a space");
  fails_with({"build", sample, "--end", "8", "--memory", uri, "--robot", " r1"}, 1, "begins or ends with a space");
}

TEST_CASE("cli: memory info refuses a sessions table changed behind the memory's back") {
  const fs::path dir = fresh_dir("sessions_rows");
  const std::string m = (dir / "m.vmdb").string();
  REQUIRE(run_vmap({"build", sample, "--memory", m, "--end", "30"}).code == 0);
  REQUIRE(run_vmap({"build", sample, "--memory", m, "--start", "30", "--session", "new"}).code == 0);
  const auto whole = nlohmann::json::parse(run_vmap({"memory", "info", m, "--json"}).out);
  REQUIRE(whole["sessions"].size() == 2);
  const std::string damaged = (dir / "d.vmdb").string();
  fs::copy_file(m, damaged);
  REQUIRE(std::system(("sqlite3 " + quote(damaged) + " \"update sessions set first_frame = 35 where id = 1\"").c_str()) == 0);
  const Run r = fails_with({"memory", "info", damaged}, 4, "is corrupt: session 1 starts at key image ");
  CHECK(r.err.find("and frame 35 in its sessions table") != std::string::npos);
}

TEST_CASE("cli: inputs that are FIFOs are refused at once by name (exit 1), bags listing one too; empty bags exit 4") {
  const fs::path dir = work_dir() / "fifo_inputs";
  fs::create_directories(dir);
  const auto refused = [](const Run& r, const std::string& message) {
    INFO("stderr: " << r.err);
    CHECK(r.code == 1);
    CHECK(r.err.find(message) != std::string::npos);
    CHECK(std::count(r.err.begin(), r.err.end(), '\n') == 1);
  };
  const std::string not_input = "' is not a regular file or a folder (a device, FIFO or socket cannot be read as one)";
  for (const char* name : {"f.bag", "f.mcap", "f.db3", "f"}) {
    const fs::path fifo = dir / name;
    REQUIRE(::mkfifo(fifo.c_str(), 0600) == 0);
    CAPTURE(name);
    refused(run_vmap_within(30, {"build", fifo.string()}), "frame source: input '" + fifo.string() + not_input);
    refused(run_vmap_within(30, {"bag", "info", fifo.string()}), "bag '" + fifo.string() + not_input);
    refused(run_vmap_within(30, {"calibrate", fifo.string(), fifo.string()}), "frame source: input '" + fifo.string() + not_input);
  }
  // A rosbag2 folder whose metadata.yaml lists a FIFO beside its .db3 file.
  const fs::path bag = dir / "listed";
  fs::create_directories(bag);
  vmap::test::write_db3(bag / "a.db3", {});
  REQUIRE(::mkfifo((bag / "b.db3").c_str(), 0600) == 0);
  write(bag / "metadata.yaml", "rosbag2_bagfile_information:\n  relative_file_paths:\n    - a.db3\n    - b.db3\n");
  const std::string listed = "bag file '" + (bag / "b.db3").string() + "' is not a regular file";
  refused(run_vmap_within(30, {"bag", "info", bag.string()}), listed);
  refused(run_vmap_within(30, {"build", bag.string()}), listed);
  // A file of 0 bytes with each bag's extension: corrupt (4) alike.
  for (const char* name : {"zero.bag", "zero.mcap", "zero.db3"}) {
    write(dir / name, "");
    CAPTURE(name);
    const Run r = run_vmap({"bag", "info", (dir / name).string()});
    INFO("stderr: " << r.err);
    CHECK(r.code == 4);
    CHECK(r.err.find((dir / name).string()) != std::string::npos);
  }
}

TEST_CASE("cli: a bag's CameraInfo of another image size is named as such, not as --camera (none was given)") {
  const fs::path dir = work_dir() / "camera_info_size";
  fs::create_directories(dir);
  // JPEG frames of 640 x 480 beside a CameraInfo for 320 x 240.
  std::vector<vmap::test::TestMessage> messages;
  const auto frames = vmap::FrameSource::open(VMAP_TEST_SOURCE_DIR + std::string("/") + sample).paths();
  for (std::size_t k = 0; k < 6; ++k) {
    const std::string jpeg = slurp(frames[k]);
    const auto t = static_cast<std::int64_t>(k + 1) * 100000000;
    messages.push_back({"/cam/camera_info", "sensor_msgs/msg/CameraInfo", t,
                        vmap::test::cdr_camera_info(t, 320, 240, "plumb_bob", {0, 0, 0, 0, 0}, {300, 0, 160, 0, 300, 120, 0, 0, 1})});
    messages.push_back({"/cam/image_raw/compressed", "sensor_msgs/msg/CompressedImage", t, vmap::test::cdr_compressed(t, "jpeg", jpeg)});
  }
  const fs::path bag = dir / "small_info.db3";
  vmap::test::write_db3(bag, messages);
  const Run r = run_vmap({"build", bag.string()});
  INFO("stderr: " << r.err);
  CHECK(r.code == 1);
  CHECK(r.err.find("camera calibration from bag '" + bag.string() + "', topic '/cam/camera_info'") != std::string::npos);
  CHECK(r.err.find("error: the CameraInfo of bag '" + bag.string() +
                   "', topic '/cam/camera_info': the calibration is for 320 x 240 images, the frames are 640 x 480") !=
        std::string::npos);
  CHECK(r.err.find("--camera " + bag.string()) == std::string::npos);
}
