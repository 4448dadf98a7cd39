// Rig observations: JSON I/O (docs/formats.md "Rig observations"), floor.json, and board
// detection over a whole take in parallel.
#include "multicam/observations.h"

#include <omp.h>

#include <atomic>
#include <set>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "core/error.h"
#include "core/io.h"
#include "core/stopwatch.h"
#include "core/threads.h"
#include "take/take.h"

namespace previz::multicam {
namespace {

namespace fs = std::filesystem;

constexpr const char* kObservationsFormat = "previz-rig-observations";
constexpr int kObservationsVersion = 1;

Error fieldError(const std::string& file, const std::string& field, const std::string& what,
                 const std::string& camera = {}) {
  ErrorContext context;
  context.file = file;
  context.field = field;
  context.camera = camera;
  return Error(what, context);
}

// Re-throws an Error from a nested reader (pose, board) with the file named.
template <typename F>
auto withFile(const std::string& file, F&& f) -> decltype(f()) {
  try {
    return f();
  } catch (const Error& e) {
    if (!e.context().file.empty()) throw;
    ErrorContext context = e.context();
    context.file = file;
    throw Error(e.message(), context);
  }
}

std::vector<int> readFrameList(const nlohmann::json& j, const std::string& file,
                               const std::string& field) {
  if (!j.is_array()) throw fieldError(file, field, field + " must be an array of frame numbers");
  std::vector<int> frames;
  for (const auto& v : j) {
    if (!v.is_number_integer() || v.get<long long>() < 0 || v.get<long long>() > 100000000) {
      throw fieldError(file, field, field + " must hold frame numbers >= 0 (got " + v.dump() + ")");
    }
    frames.push_back(v.get<int>());
  }
  std::sort(frames.begin(), frames.end());
  frames.erase(std::unique(frames.begin(), frames.end()), frames.end());
  return frames;
}

nlohmann::json floorToJson(const FloorSpec& floor) {
  return {{"board", boardToJson(floor.board)},
          {"frames", floor.frames},
          {"T_world_board", poseToJson(floor.T_world_board)}};
}

// base: folder a board path in "board" is relative to.
FloorSpec floorFromJson(const nlohmann::json& j, const std::string& file, const fs::path& base) {
  if (!j.is_object()) throw fieldError(file, "floor", "floor must be a JSON object");
  FloorSpec floor;
  if (!j.contains("board")) throw fieldError(file, "board", "floor: 'board' is missing (board.json path or board object)");
  const nlohmann::json& jb = j.at("board");
  if (jb.is_string()) {
    fs::path board_path = jb.get<std::string>();
    if (board_path.is_relative()) board_path = base / board_path;
    floor.board = readBoard(board_path);
  } else if (jb.is_object()) {
    floor.board = withFile(file, [&] { return boardFromJson(jb, file); });
  } else {
    throw fieldError(file, "board", "floor: 'board' must be a path or a board object (got " + jb.dump() + ")");
  }
  if (!j.contains("frames")) throw fieldError(file, "frames", "floor: 'frames' is missing");
  floor.frames = readFrameList(j.at("frames"), file, "frames");
  if (floor.frames.empty()) throw fieldError(file, "frames", "floor: 'frames' is empty");
  if (j.contains("T_world_board")) {
    floor.T_world_board = withFile(file, [&] { return poseFromJson(j.at("T_world_board"), "T_world_board"); });
  }
  return floor;
}

struct Item {
  int camera = 0;
  int frame = 0;
};

// Result of one (camera, frame); filled inside the parallel region, merged in index order.
struct ItemResult {
  cv::Size size;
  std::vector<calib::Observation> points;
  std::string failure;  // image unreadable
};

}  // namespace

FloorSpec readFloor(const fs::path& path) {
  const nlohmann::json j = readJsonFile(path);
  return floorFromJson(j, path.string(), path.parent_path());
}

void writeFloor(const FloorSpec& floor, const fs::path& path) {
  withFile(path.string(), [&] { floor.board.validate(); });
  writeJsonAtomic(path, floorToJson(floor));
}

nlohmann::json observationsToJson(const RigObservations& obs) {
  nlohmann::json cameras = nlohmann::json::array();
  for (const CameraDetections& c : obs.cameras) {
    nlohmann::json frames = nlohmann::json::array();
    for (const auto& [frame, points] : c.frames) {
      nlohmann::json pts = nlohmann::json::array();
      for (const calib::Observation& o : points) pts.push_back({o.id, o.px.x(), o.px.y()});
      frames.push_back({{"frame", frame}, {"points", pts}});
    }
    nlohmann::json failures = nlohmann::json::array();
    for (const auto& [frame, reason] : c.failures) failures.push_back({{"frame", frame}, {"reason", reason}});
    cameras.push_back({{"name", c.camera},
                       {"width", c.image_size.width},
                       {"height", c.image_size.height},
                       {"frames", frames},
                       {"failures", failures}});
  }
  return {{"format", kObservationsFormat},
          {"version", kObservationsVersion},
          {"pixel_origin", "pixel (0,0) is the centre of the top-left pixel"},
          {"points", "[board point id (core/board.h), x px, y px]"},
          {"board", boardToJson(obs.board)},
          {"frame_count", obs.frame_count},
          {"floor", obs.has_floor ? floorToJson(obs.floor) : nlohmann::json()},
          {"cameras", cameras}};
}

RigObservations observationsFromJson(const nlohmann::json& j, const std::string& file) {
  if (!j.is_object()) throw fieldError(file, "(root)", "rig observations must be a JSON object");
  if (!j.contains("format") || j.at("format") != kObservationsFormat) {
    throw fieldError(file, "format", std::string("not a rig observations file (format must be '") +
                                         kObservationsFormat + "')");
  }
  if (!j.contains("version") || !j.at("version").is_number_integer() ||
      j.at("version").get<int>() > kObservationsVersion) {
    throw fieldError(file, "version", "unsupported rig observations version (this previz reads " +
                                          std::to_string(kObservationsVersion) + ")");
  }
  RigObservations obs;
  if (!j.contains("board")) throw fieldError(file, "board", "'board' is missing");
  obs.board = withFile(file, [&] { return boardFromJson(j.at("board"), file); });
  if (!j.contains("frame_count") || !j.at("frame_count").is_number_integer() ||
      j.at("frame_count").get<long long>() < 0) {
    throw fieldError(file, "frame_count", "'frame_count' must be an integer >= 0");
  }
  obs.frame_count = j.at("frame_count").get<int>();
  if (j.contains("floor") && !j.at("floor").is_null()) {
    obs.floor = floorFromJson(j.at("floor"), file, fs::path(file).parent_path());
    obs.has_floor = true;
  }
  if (!j.contains("cameras") || !j.at("cameras").is_array()) {
    throw fieldError(file, "cameras", "'cameras' must be an array");
  }
  std::set<std::string> names;
  for (const nlohmann::json& jc : j.at("cameras")) {
    CameraDetections c;
    if (!jc.is_object() || !jc.contains("name") || !jc.at("name").is_string()) {
      throw fieldError(file, "cameras.name", "every camera needs a 'name' string");
    }
    c.camera = jc.at("name").get<std::string>();
    if (!names.insert(c.camera).second) throw fieldError(file, "cameras.name", "camera listed twice", c.camera);
    auto integer = [&](const char* key) {
      if (!jc.contains(key) || !jc.at(key).is_number_integer() || jc.at(key).get<long long>() < 0) {
        throw fieldError(file, std::string("cameras.") + key, std::string("'") + key + "' must be an integer >= 0", c.camera);
      }
      return jc.at(key).get<int>();
    };
    c.image_size = cv::Size(integer("width"), integer("height"));
    if (jc.contains("frames")) {
      if (!jc.at("frames").is_array()) throw fieldError(file, "cameras.frames", "'frames' must be an array", c.camera);
      for (const nlohmann::json& jf : jc.at("frames")) {
        if (!jf.is_object() || !jf.contains("frame") || !jf.at("frame").is_number_integer() ||
            !jf.contains("points") || !jf.at("points").is_array()) {
          throw fieldError(file, "cameras.frames", "each frame needs 'frame' (integer) and 'points' (array)", c.camera);
        }
        const int frame = jf.at("frame").get<int>();
        std::vector<calib::Observation>& points = c.frames[frame];
        for (const nlohmann::json& jp : jf.at("points")) {
          if (!jp.is_array() || jp.size() != 3 || !jp[0].is_number_integer() || !jp[1].is_number() ||
              !jp[2].is_number()) {
            ErrorContext context;
            context.file = file;
            context.camera = c.camera;
            context.frame = frame;
            context.field = "points";
            throw Error("a point must be [id, x, y] (got " + jp.dump() + ")", context);
          }
          calib::Observation o;
          o.id = jp[0].get<int>();
          o.px = Eigen::Vector2d(jp[1].get<double>(), jp[2].get<double>());
          points.push_back(o);
        }
      }
    }
    if (jc.contains("failures") && jc.at("failures").is_array()) {
      for (const nlohmann::json& jf : jc.at("failures")) {
        if (!jf.is_object() || !jf.contains("frame") || !jf.at("frame").is_number_integer()) {
          throw fieldError(file, "cameras.failures", "each failure needs 'frame'", c.camera);
        }
        c.failures[jf.at("frame").get<int>()] = jf.value("reason", std::string());
      }
    }
    obs.cameras.push_back(std::move(c));
  }
  return obs;
}

void writeObservations(const RigObservations& obs, const fs::path& path) {
  // Compact: a 300-frame rig take holds ~10^5 points.
  writeJsonAtomic(path, observationsToJson(obs), -1);
}

RigObservations readObservations(const fs::path& path) {
  return observationsFromJson(readJsonFile(path), path.string());
}

std::vector<std::string> takeCameras(const fs::path& take) {
  const fs::path take_json = take / "take.json";
  if (fs::exists(take_json)) {
    const nlohmann::json j = readJsonFile(take_json);
    if (j.contains("cameras")) {
      const nlohmann::json& jc = j.at("cameras");
      std::vector<std::string> names;
      if (jc.is_array()) {
        for (const auto& v : jc) {
          if (v.is_string()) names.push_back(v.get<std::string>());
        }
      }
      if (names.size() != jc.size() || names.empty()) {
        throw fieldError(take_json.string(), "cameras", "take: 'cameras' must be a non-empty array of names");
      }
      return names;
    }
  }
  const fs::path cams = take / "cams";
  std::vector<std::string> names;
  if (fs::is_directory(cams)) {
    for (const auto& entry : fs::directory_iterator(cams)) {
      if (entry.is_directory()) names.push_back(entry.path().filename().string());
    }
  }
  std::sort(names.begin(), names.end());
  if (names.empty()) {
    ErrorContext context;
    context.file = take.string();
    throw Error("take: no cameras (no take.json 'cameras' and no folders under cams/)", context);
  }
  return names;
}

RigObservations detectTake(const fs::path& take, const std::vector<std::string>& cameras,
                           const BoardSpec& board, const FloorSpec* floor,
                           const DetectTakeOptions& options,
                           const std::function<void(const DetectProgress&)>& progress) {
  options.detect.validate();
  board.validate();
  if (floor) floor->board.validate();
  if (cameras.empty()) {
    ErrorContext context;
    context.file = take.string();
    throw Error("detect: no cameras given", context);
  }
  take::TakeOptions streams;
  streams.cameras = cameras;
  const take::Take streams_of(take, streams);
  for (const std::string& name : cameras) {
    const take::CameraStream& s = streams_of.stream(name);
    if (s.kind == take::SourceKind::kNone) {
      ErrorContext context;
      context.file = (take / "cams" / name).string();
      context.camera = name;
      throw Error("detect: camera '" + name + "' has no stream: " + s.unusable, context);
    }
  }
  RigObservations obs;
  obs.board = board;
  // Frames 0 .. the last take frame any camera has (or take.json's count).
  obs.frame_count = streams_of.frames().empty() ? 0 : streams_of.frames().back() + 1;
  if (floor) {
    obs.has_floor = true;
    obs.floor = *floor;
  }
  const int first = std::max(0, options.first_frame);
  const int last = options.last_frame < 0 ? obs.frame_count - 1 : std::min(options.last_frame, obs.frame_count - 1);

  std::vector<Item> items;
  for (int c = 0; c < static_cast<int>(cameras.size()); ++c) {
    for (int f = first; f <= last; ++f) items.push_back({c, f});
  }
  std::vector<ItemResult> results(items.size());
  const int total = static_cast<int>(items.size());
  std::atomic<int> done{0};
  const Stopwatch start;
  std::string progress_error;
  const int threads = resolveThreads(options.threads);

  // Each item is independent; errors are recorded per item (STYLE.md rule 11).
#pragma omp parallel for schedule(dynamic, 1) num_threads(threads)
  for (int i = 0; i < total; ++i) {
    const Item& item = items[i];
    ItemResult& r = results[i];
    try {
      const take::CameraImage frame = streams_of.read(cameras[item.camera], item.frame);
      if (!frame.ok()) throw Error(frame.dropped);
      const cv::Mat& image = frame.image;
      const std::string file = (take / frame.source).string();
      r.size = image.size();
      const BoardSpec& spec = obs.boardOf(item.frame);
      const calib::ViewObservations view = calib::detectBoard(image, spec, options.detect, file);
      r.points = view.points;
    } catch (const std::exception& e) {
      r.failure = e.what();
    }
    const int now = ++done;
    if (progress) {
#pragma omp critical(previz_detect_take_progress)
      {
        try {
          DetectProgress p;
          p.images_done = now;
          p.images_total = total;
          p.elapsed_s = start.seconds();
          progress(p);
        } catch (const std::exception& e) {
          if (progress_error.empty()) progress_error = e.what();
        }
      }
    }
  }
  if (!progress_error.empty()) throw Error("detect: progress callback failed: " + progress_error);

  // Merge in index order; the image size of a camera is that of its first readable frame, and a
  // frame of another size is a failure (a mixed-up folder, not a different camera).
  for (int c = 0; c < static_cast<int>(cameras.size()); ++c) {
    CameraDetections cam;
    cam.camera = cameras[c];
    for (int i = 0; i < total; ++i) {
      if (items[i].camera != c) continue;
      const ItemResult& r = results[i];
      const int frame = items[i].frame;
      if (!r.failure.empty()) {
        cam.failures[frame] = r.failure;
        continue;
      }
      if (cam.image_size.empty()) cam.image_size = r.size;
      if (r.size != cam.image_size) {
        cam.failures[frame] = "image is " + std::to_string(r.size.width) + "x" + std::to_string(r.size.height) +
                              ", the camera's other frames " + std::to_string(cam.image_size.width) + "x" +
                              std::to_string(cam.image_size.height);
        continue;
      }
      if (!r.points.empty()) cam.frames[frame] = r.points;
    }
    obs.cameras.push_back(std::move(cam));
  }
  return obs;
}

}  // namespace previz::multicam
