// Bad input, app by app: a table of cases per app, each run as a user would.
// Every case must end with exit 2 (bad input) or 3 (numerical failure), one
// line on stderr naming the key, flag or file, and no result file written.
// The classes: malformed and doctored files (checkpoints, TorchScript models,
// PNG/EXR images, metrics.csv), NaN/Inf data, configs and --set values of
// every wrong kind (too deep, numbers no double holds, invalid UTF-8, out of
// range), stray or repeated arguments, and output paths that cannot be written.
#include <catch2/catch.hpp>
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <torch/script.h>
#include <torch/torch.h>

#include "common/atomic_file.h"
#include "common/tensor_io.h"
#include "data/image_io.h"
#include "data/scene_exr.h"
#include "helpers.h"

using namespace hsd;
namespace fs = std::filesystem;

namespace {

using test::run;
using test::Run;

struct Case {
  std::string args;      // after the app's name
  int code;              // 2 or 3
  std::string names;     // the key, flag or file the line must name
  std::string no_file;   // a result file that must not exist afterwards ("" = none)
};

// The error is one line, the last; any line before it is one of hsd's own
// progress lines ("threads: 2"), never a library's message or a second error.
void check_one_line(const std::string& app, const std::string& err) {
  std::vector<std::string> ls;
  std::string line;
  for (char c : err) {
    if (c == '\n') ls.push_back(line), line.clear();
    else line += c;
  }
  if (!line.empty()) ls.push_back(line);
  REQUIRE(!ls.empty());
  CHECK((ls.back().rfind(app + ": error: ", 0) == 0 || ls.back().rfind(app + ": numerical error: ", 0) == 0));
  for (size_t i = 0; i + 1 < ls.size(); ++i) {
    INFO("line " << i << ": " << ls[i]);
    CHECK(ls[i].rfind("threads: ", 0) == 0);
  }
}

void check_table(const std::string& app_and_args, const std::vector<Case>& cases) {
  const std::string app = app_and_args.substr(0, app_and_args.find(' '));
  for (const auto& c : cases) {
    if (!c.no_file.empty()) fs::remove_all(c.no_file);
    const Run r = run(app_and_args + " " + c.args);
    INFO(app_and_args << " " << c.args << "\nstderr: " << r.err);
    CHECK(r.code == c.code);
    CHECK_THAT(r.err, Catch::Contains(c.names));
    check_one_line(app, r.err);
    if (!c.no_file.empty()) CHECK_FALSE(fs::exists(c.no_file));
  }
}

// One tiny trained run, its export and doctored copies, shared by the tables.
struct Fixture {
  // One folder per test process: ctest -j runs the cases of this file side by side.
  fs::path base = fs::temp_directory_path() / ("hsd_test_bad_input_" + std::to_string(::getpid()));
  std::string sets, cfg, ckpt, model;
  // An empty folder `name` below base for one test case's files.
  fs::path fresh_folder(const std::string& name) const {
    const fs::path d = base / name;
    fs::remove_all(d);
    fs::create_directories(d);
    return d;
  }
  ~Fixture() {
    std::error_code ec;
    fs::remove_all(base, ec);
  }
  Fixture() {
    fs::remove_all(base);
    fs::create_directories(base);
    sets = test::tiny_run_sets(base / "data");
    cfg = "--config configs/tiny.json" + sets;
    ckpt = (base / "run/checkpoints/last.pt").string();
    model = (base / "export/reconstructor.pt").string();
    const Run t = run("hsd_train " + cfg + " --out " + (base / "run").string());
    const Run e = run("hsd_export " + cfg + " --checkpoint " + ckpt + " --out " + (base / "export").string());
    ok = t.code == 0 && e.code == 0;
    // Doctored checkpoints.
    const TensorDict good = load_tensor_dict(ckpt);
    auto doctor = [&](const std::string& name, const std::function<void(TensorDict&)>& f) {
      TensorDict d = good;
      f(d);
      save_tensor_dict((base / name).string(), d);
    };
    std::string weight;
    for (const auto& [k, v] : good)
      if (k.rfind("net.", 0) == 0 && v.is_floating_point() && v.numel() > 1) { weight = k; break; }
    doctor("nan_weight.pt", [&](TensorDict& d) { d[weight] = d[weight].clone(); d[weight].view(-1)[0] = NAN; });
    doctor("inf_doe.pt", [&](TensorDict& d) { d["doe.raw"] = d["doe.raw"].clone(); d["doe.raw"].view(-1)[3] = INFINITY; });
    doctor("no_adam_step.pt", [&](TensorDict& d) { d.erase("adam.0.0.step"); });
    doctor("step_pair.pt", [&](TensorDict& d) { d["step"] = torch::tensor({2, 3}, torch::kInt64); });
    doctor("adam_shape.pt", [&](TensorDict& d) { d["adam.0.0.exp_avg"] = torch::zeros({1}); });
    // TorchScript modules with the right attributes: wrong output shapes, NaN output.
    auto module = [&](const std::string& name, const std::string& forward) {
      torch::jit::Module m("Fake");
      m.register_attribute("wavelengths_m", c10::TensorType::get(), torch::tensor({450e-9, 550e-9, 650e-9}, torch::kFloat64));
      m.register_attribute("depth_range_m", c10::TensorType::get(), torch::tensor({0.4, 2.0}, torch::kFloat64));
      m.define("def forward(self, x):\n" + forward);
      m.save((base / name).string());
    };
    module("wrong_shape.pt", "    return (x[:, 0:1], x)\n");
    module("nan_out.pt", "    return (x * float('nan'), x[:, 0:1] + 1.0)\n");
    // Images: a PNG claiming 100000 x 100000 pixels, a truncated PNG, an EXR with a NaN pixel.
    {
      std::ofstream f(base / "huge.png", std::ios::binary);
      const unsigned char png[] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n', 0, 0, 0, 13, 'I', 'H', 'D', 'R',
                                   0, 1, 0x86, 0xa0, 0, 1, 0x86, 0xa0, 8, 2, 0, 0, 0, 0, 0, 0, 0,
                                   0, 0, 0, 0, 'I', 'E', 'N', 'D', 0xae, 0x42, 0x60, 0x82};
      f.write(reinterpret_cast<const char*>(png), sizeof png);
    }
    data::write_srgb_png((base / "frame.png").string(), torch::rand({3, 40, 40}));
    {
      const auto bytes = read_binary_file((base / "frame.png").string());
      write_binary_file((base / "cut.png").string(), std::vector<char>(bytes.begin(), bytes.begin() + long(bytes.size() / 2)));
    }
    torch::Tensor rgb = torch::rand({3, 40, 40});
    rgb[1][7][5] = NAN;
    data::write_channels_exr((base / "nan.exr").string(), rgb, {"R", "G", "B"});
    // Configs: nested 200,000 levels (an object, and an array under _note), a number no double holds.
    {
      std::ofstream f(base / "deep.json");
      f << "{\"extends\": \"" << test::source_path("configs/tiny.json") << "\", \"x\": ";
      for (int i = 0; i < 200000; ++i) f << "{\"a\": ";
      f << "1";
      for (int i = 0; i < 200000; ++i) f << "}";
      f << "}";
      std::ofstream g(base / "deep_note.json");
      g << "{\"extends\": \"" << test::source_path("configs/tiny.json") << "\", \"_note\": " << std::string(200000, '[')
        << std::string(200000, ']') << "}";
      std::ofstream h(base / "overflow.json");
      h << "{\"extends\": \"" << test::source_path("configs/tiny.json") << "\", \"train\": {\"lr_net\": 1e400}}";
    }
    fs::create_directories(base / "taken/metrics.json");  // an output name taken by a folder
  }
  bool ok = false;
};

Fixture& fixture() {
  static Fixture f;
  return f;
}

}  // namespace

TEST_CASE("bad input: every app refuses stray, repeated and malformed arguments and configs", "[app][bad_input]") {
  Fixture& F = fixture();
  REQUIRE(F.ok);
  const std::string out = (F.base / "o").string(), b = F.base.string();
  // The same config and flag cases for every app that reads a config.
  for (std::string app : {"hsd_train", "hsd_eval", "hsd_export", "hsd_fisher", "hsd_psf", "hsd_scenes", "hsd_simulate",
                          "hsd_import", "hsd_ablate"}) {
    if (app == "hsd_simulate") app += " --scene " + b + "/data/scene_test_000.exr";  // checked before the config
    check_table(app, {
        {F.cfg + " --set train.steps=1 train.batch_size=0 --out " + out, 2, "train.batch_size=0", ""},
        {F.cfg + " --out " + out + " --out " + out, 2, "--out", ""},
        {"--config " + b + "/deep.json --out " + out, 2, "deep.json", ""},
        {"--config " + b + "/deep_note.json --out " + out, 2, "deep_note.json", ""},
        {"--config " + b + "/overflow.json --out " + out, 2, "overflow.json", ""},
        {F.cfg + " --set train.steps=1e400 --out " + out, 2, "train.steps", ""},
        {F.cfg + " --set fisher.photons=1e999 --out " + out, 2, "fisher.photons", ""},
        {F.cfg + " --set \"data.root=$(printf 'x\\377y')\" --out " + out, 2, "data.root", ""},
        {F.cfg + " --set model.levels=5 --out " + out, 2, "model.levels", ""},
        {F.cfg + " --set model.preinverse=fft --out " + out, 2, "model.preinverse", ""},
        {F.cfg + " --set model.residual=wiener --out " + out, 2, "model.residual", ""},
        {F.cfg + " --set model.preinverse=none --set model.residual=preinverse --out " + out, 2, "model.residual", ""},
        {F.cfg + " --set train.depth_loss=l2 --out " + out, 2, "train.depth_loss", ""},
        {F.cfg + " --set fisher.model=gaussian --out " + out, 2, "fisher.model", ""},
        {F.cfg + " --set fisher.scene_noise_variance=0 --out " + out, 2, "fisher.scene_noise_variance", ""},
        {F.cfg + " --set train.steps=0 --out " + out, 2, "train.steps", ""},
        {F.cfg + " --set \"_note=$(printf '[%.0s' $(seq 100))$(printf ']%.0s' $(seq 100))\" --out " + out, 2, "_note", ""},
    });
  }
}

TEST_CASE("bad input: hsd_train refuses doctored checkpoints and metrics for --resume and untaken outputs", "[app][bad_input]") {
  Fixture& F = fixture();
  REQUIRE(F.ok);
  const fs::path r = F.base / "resume";
  auto prepare = [&](const std::string& ckpt, const std::string& csv) {
    fs::remove_all(r);
    fs::create_directories(r / "checkpoints");
    fs::copy_file(ckpt, r / "checkpoints/last.pt");
    std::ofstream(r / "metrics.csv") << csv;
  };
  const std::string header = "step,wall_s,train_loss,val_loss\n";
  const std::string resume = F.cfg + " --resume --out " + r.string();
  struct ResumeCase { std::string ckpt, csv; int code; std::string names; };
  const std::vector<ResumeCase> cases = {
      {F.ckpt, header + "0\n", 2, "metrics.csv"},                       // a row shorter than the header
      {F.ckpt, header + "zero,1,2,3\n", 2, "metrics.csv"},              // a step that is not a number
      {(F.base / "nan_weight.pt").string(), header, 2, "NaN"},
      {(F.base / "inf_doe.pt").string(), header, 2, "doe.raw"},
      {(F.base / "no_adam_step.pt").string(), header, 2, "adam.0.0.step"},
      {(F.base / "step_pair.pt").string(), header, 2, "step"},
      {(F.base / "adam_shape.pt").string(), header, 2, "adam.0.0.exp_avg"},
  };
  for (const auto& c : cases) {
    prepare(c.ckpt, c.csv);
    const Run x = run("hsd_train " + resume);
    INFO("checkpoint " << c.ckpt << ", metrics.csv \"" << c.csv << "\"\nstderr: " << x.err);
    CHECK(x.code == c.code);
    CHECK_THAT(x.err, Catch::Contains(c.names));
    check_one_line("hsd_train", x.err);
  }
  check_table("hsd_train", {
      {F.cfg + " --resume yes --out " + r.string(), 2, "yes", ""},
      {F.cfg + " --resume --out " + (F.base / "nothing").string(), 2, "last.pt", ""},
  });
  // An output name taken by a folder is refused before any data or training.
  fs::remove_all(r);
  fs::create_directories(r / "checkpoints/last.pt");
  const Run t = run("hsd_train " + F.cfg + " --out " + r.string());
  CHECK(t.code == 2);
  CHECK_THAT(t.err, Catch::Contains("last.pt"));
  CHECK_FALSE(fs::exists(r / "metrics.csv"));
}

TEST_CASE("bad input: hsd_eval and hsd_export refuse NaN checkpoints and models and write no result", "[app][bad_input]") {
  Fixture& F = fixture();
  REQUIRE(F.ok);
  const std::string b = F.base.string(), out = b + "/ev", ex = b + "/ex";
  check_table("hsd_eval", {
      {F.cfg + " --checkpoint " + b + "/nan_weight.pt --out " + out, 2, "nan_weight.pt", out + "/metrics.json"},
      {F.cfg + " --checkpoint " + b + "/inf_doe.pt --out " + out, 2, "inf_doe.pt", out + "/metrics.json"},
      {F.cfg + " --model " + b + "/nope.pt --out " + out, 2, "nope.pt", out + "/metrics.json"},
      {F.cfg + " --model " + b + "/wrong_shape.pt --doe " + b + "/export/doe_height.pt --out " + out, 2, "wrong_shape.pt",
       out + "/metrics.json"},
      {F.cfg + " --model " + b + "/nan_out.pt --doe " + b + "/export/doe_height.pt --out " + out, 2, "nan_out.pt",
       out + "/metrics.json"},
      {F.cfg + " --checkpoint " + F.ckpt + " --out " + b + "/taken", 2, "metrics.json", ""},
      {F.cfg + " --checkpoint " + F.ckpt + " extra --out " + out, 2, "extra", out + "/metrics.json"},
  });
  check_table("hsd_export", {
      {F.cfg + " --checkpoint " + b + "/nan_weight.pt --out " + ex, 2, "nan_weight.pt", ex + "/reconstructor.pt"},
      {F.cfg + " --checkpoint " + b + "/inf_doe.pt --out " + ex, 2, "inf_doe.pt", ex + "/reconstructor.pt"},
      {F.cfg + " --checkpoint " + F.ckpt + " again --out " + ex, 2, "again", ex + "/reconstructor.pt"},
  });
  CHECK_FALSE(fs::exists(ex + "/doe_height.pt"));
}

TEST_CASE("bad input: hsd_reconstruct refuses damaged images and models and writes no cube", "[app][bad_input]") {
  Fixture& F = fixture();
  REQUIRE(F.ok);
  const std::string b = F.base.string(), out = b + "/rec";
  const std::string m = " --model " + F.model + " --tile 32 --overlap 0 --out " + out;
  check_table("hsd_reconstruct", {
      {"--input " + b + "/nan.exr" + m, 2, "nan.exr", out + "/hs.exr"},
      {"--input " + b + "/huge.png" + m, 2, "huge.png", out + "/hs.exr"},
      {"--input " + b + "/cut.png" + m, 2, "cut.png", out + "/hs.exr"},
      {"--input " + b + "/frame.png " + b + "/cut.png" + m, 2, "cut.png", out + "/hs.exr"},
      {"--input " + b + "/frame.png --model " + b + "/wrong_shape.pt --out " + out, 2, "wrong_shape.pt", out + "/hs.exr"},
      {"--input " + b + "/frame.png --model " + b + "/nan_out.pt --out " + out, 2, "nan_out.pt", out + "/hs.exr"},
      {"--input " + b + "/frame.png --model " + b + "/frame.png --out " + out, 2, "frame.png", out + "/hs.exr"},
  });
}

TEST_CASE("bad input: hsd_import, hsd_bench and hsd_ablate refuse inconsistent flags and arguments", "[app][bad_input]") {
  Fixture& F = fixture();
  REQUIRE(F.ok);
  const std::string b = F.base.string(), rgbd = " --rgb " + b + "/frame.png --disparity " + b + "/frame.png";
  check_table("hsd_import", {
      {F.cfg + rgbd + " --focal-px 0 --baseline-m 0.1 --doffs-px 0 --out " + b + "/imp", 2, "--focal-px", ""},
      {F.cfg + rgbd + " --baseline-m 0.1 --out " + b + "/imp", 2, "--focal-px", ""},
      {F.cfg + " --rgb " + b + "/huge.png --disparity " + b + "/frame.png --out " + b + "/imp", 2, "huge.png", ""},
  });
  check_table("hsd_bench", {
      {"psf extra", 2, "extra", ""},
      {"nosuch --config configs/tiny.json", 2, "nosuch", ""},
      {"psf --config " + b + "/deep.json", 2, "deep.json", ""},
      {"psf --config configs/tiny.json --set fisher.photons=1e999", 2, "fisher.photons", ""},
      {"psf --threads two", 2, "--threads", ""},
      // paper.json before hsd_fisher has run (a fresh clone): the fallback's note must not come first
      {"psf --set optics.doe.fisher_path=\\\"" + b + "/no_fisher.pt\\\" --threads two", 2, "--threads", ""},
      {"psf --set optics.doe.fisher_path=\\\"" + b + "/no_fisher.pt\\\" --repeats x", 2, "--repeats", ""},
      {"psf --json --json", 2, "--json", ""},
  });
  check_table("hsd_ablate", {
      {F.cfg + " --seeds '' --out " + b + "/abl", 2, "--seeds", ""},
      {F.cfg + " --seeds 0,0 --out " + b + "/abl", 2, "--seeds", ""},
      {F.cfg + " --seeds 0, --out " + b + "/abl", 2, "--seeds", ""},
  });
}

TEST_CASE("bad input: hsd_calibrate, PSF files, init checkpoints and --camera-psf are refused naming the file or key", "[app][bad_input][calibration]") {
  Fixture& F = fixture();
  REQUIRE(F.ok);
  const fs::path b = F.fresh_folder("cal");
  const std::string caps = (b / "caps").string(), out = (b / "out").string();
  REQUIRE(run("hsd_calibrate " + F.cfg + " --set calibration.synthetic.exposures=1 --make-captures --out " + caps).code == 0);
  // Doctored capture folders: each a copy of the good one with one thing wrong.
  const Json good = Json::parse(std::ifstream(caps + "/captures.json"));
  auto folder = [&](const std::string& name, const std::function<void(Json&)>& edit) {
    const fs::path d = b / name;
    fs::remove_all(d);
    fs::copy(caps, d);
    Json j = good;
    edit(j);
    std::ofstream(d / "captures.json") << j.dump(1);
    return d.string();
  };
  const std::string wrong_wl = folder("wrong_wl", [](Json& j) { j["wavelengths_nm"][0] = 440; });
  const std::string missing = folder("missing", [](Json& j) { j["files"][1][0] = "nowhere.png"; });
  const std::string short_row = folder("short_row", [](Json& j) { j["files"][0].erase(1); });
  const std::string saturated = folder("saturated", [](Json&) {});
  {  // one capture clipped at the sensor's maximum over a 3x3 block at its peak
    const std::string f = saturated + "/" + good["files"][0][0][0].get<std::string>();
    cv::Mat m = cv::imread(f, cv::IMREAD_UNCHANGED);
    double mx;
    cv::Point at;
    cv::minMaxLoc(m, nullptr, &mx, nullptr, &at);
    m(cv::Rect(at.x - 1, at.y - 1, 3, 3)).setTo(65535);
    cv::imwrite(f, m);
  }
  const std::string dark_only = folder("dark_only", [](Json&) {});
  {  // a capture with no point source: the dark frame itself
    const std::string f = dark_only + "/" + good["files"][2][1][0].get<std::string>();
    fs::copy_file(dark_only + "/" + good["dark"][0].get<std::string>(), f, fs::copy_options::overwrite_existing);
  }
  const std::string rgb = folder("rgb", [](Json&) {});
  {
    const std::string f = rgb + "/" + good["files"][0][1][0].get<std::string>();
    cv::imwrite(f, cv::Mat(61, 61, CV_8UC3, cv::Scalar(1, 2, 3)));
  }
  check_table("hsd_calibrate", {
      {F.cfg + " --captures " + b.string() + "/nothing --out " + out, 2, "captures.json", out + "/psf.pt"},
      {F.cfg + " --captures " + wrong_wl + " --out " + out, 2, "wavelengths_nm", out + "/psf.pt"},
      {F.cfg + " --captures " + missing + " --out " + out, 2, "nowhere.png", out + "/psf.pt"},
      {F.cfg + " --captures " + short_row + " --out " + out, 2, "files[0]", out + "/psf.pt"},
      {F.cfg + " --captures " + saturated + " --out " + out, 2, "saturated", out + "/psf.pt"},
      {F.cfg + " --captures " + dark_only + " --out " + out, 2, "no signal", out + "/psf.pt"},
      {F.cfg + " --captures " + rgb + " --out " + out, 2, "single-channel", out + "/psf.pt"},
      {F.cfg + " --captures " + caps + " --set calibration.registration=axle --out " + out, 2, "calibration.registration", ""},
      {F.cfg + " --out " + out, 2, "--captures/--make-captures", ""},
      {F.cfg + " --captures " + caps + " --make-captures --out " + out, 2, "--captures/--make-captures", ""},
  });
  // PSF files as the imaging PSFs, and checkpoints to start from.
  const std::string truth = caps + "/truth_psf.pt", run_out = (b / "train").string();
  TensorDict t = load_tensor_dict(truth);
  t["depths_m"] = torch::tensor({0.5, 2.5}, torch::kFloat64);
  save_tensor_dict((b / "other_depths.pt").string(), t);
  check_table("hsd_train", {
      {F.cfg + " --set optics.psf_source=file: --out " + run_out, 2, "optics.psf_source", ""},
      {F.cfg + " --set optics.psf_source=file:" + b.string() + "/none.pt --out " + run_out, 2, "none.pt", run_out + "/metrics.csv"},
      {F.cfg + " --set optics.psf_source=file:" + b.string() + "/other_depths.pt --out " + run_out, 2, "optics.psf_source",
       run_out + "/metrics.csv"},
      {F.cfg + " --set train.init_checkpoint=" + b.string() + "/none.pt --out " + run_out, 2, "none.pt", run_out + "/metrics.csv"},
      {F.cfg + " --set train.init_checkpoint=" + F.base.string() + "/nan_weight.pt --out " + run_out, 2, "nan_weight.pt",
       run_out + "/metrics.csv"},
      {F.cfg + " --set model.base_width=8 --set train.init_checkpoint=" + F.ckpt + " --out " + run_out, 2, "train.init_checkpoint",
       run_out + "/metrics.csv"},
      {F.cfg + " --set optics.field_angle_deg=8 --out " + run_out, 2, "optics.field_angle_deg", run_out + "/metrics.csv"},
      {F.cfg + " --set optics.field_angle_deg=45 --out " + run_out, 2, "optics.field_angle_deg", run_out + "/metrics.csv"},
  });
  check_table("hsd_eval", {
      {F.cfg + " --checkpoint " + F.ckpt + " --camera-psf " + b.string() + "/other_depths.pt --out " + out, 2, "--camera-psf",
       out + "/metrics.json"},
  });
  check_table("hsd_simulate --scene " + F.base.string() + "/data/scene_test_000.exr", {
      {F.cfg + " --set optics.psf_source=file:" + b.string() + "/none.pt --out " + out, 2, "none.pt", out + "/sensor.exr"},
  });
}

TEST_CASE("bad input: hsd_fabricate refuses missing, NaN and mismatched DOEs and bad fabrication keys, writing nothing", "[app][bad_input][fabrication]") {
  Fixture& F = fixture();
  REQUIRE(F.ok);
  const fs::path b = F.fresh_folder("fab");
  const std::string out = (b / "out").string(), gds = out + "/masks.gds";
  TensorDict d = load_tensor_dict(F.ckpt);
  d["height_map_m"] = torch::zeros({32, 32});
  save_tensor_dict((b / "small.pt").string(), d);
  d = load_tensor_dict(F.ckpt);
  d["height_map_m"][3][4] = std::nanf("");
  save_tensor_dict((b / "nan.pt").string(), d);
  check_table("hsd_fabricate", {
      {F.cfg + " --out " + out, 2, "--doe", gds},
      {F.cfg + " --doe " + b.string() + "/none.pt --out " + out, 2, "none.pt", gds},
      {F.cfg + " --doe " + b.string() + "/small.pt --out " + out, 2, "small.pt", gds},
      {F.cfg + " --doe " + b.string() + "/nan.pt --out " + out, 2, "nan.pt", gds},
      {F.cfg + " --doe " + F.ckpt + " --set fabrication.levels=6 --out " + out, 2, "fabrication.levels", gds},
      {F.cfg + " --doe " + F.ckpt + " --set fabrication.cell_name=\"my cell\" --out " + out, 2, "fabrication.cell_name", gds},
      {F.cfg + " --doe " + F.ckpt + " --set fabrication.tolerance.edge_blur_m=[0,2e-06,1e-06] --tolerance --out " + out, 2,
       "fabrication.tolerance.edge_blur_m", gds},
      {F.cfg + " --doe " + F.ckpt + " --set optics.doe_pitch_m=8.0005e-06 --out " + out, 2, "optics.doe_pitch_m", gds},
      {F.cfg + " --doe " + F.ckpt + " --tolerance yes --out " + out, 2, "yes", gds},
  });
}
