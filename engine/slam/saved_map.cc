#include "engine/slam/saved_map.h"

#include <cstring>
#include <fstream>
#include <iterator>
#include <stdexcept>

#include "engine/util/check.h"

namespace omnirig::slam {
namespace {

static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "the map file is little-endian");

constexpr char kMagic[12] = {'O', 'M', 'N', 'I', 'R', 'I', 'G', '-', 'M', 'A', 'P', '\n'};
constexpr char kEnd[4] = {'E', 'N', 'D', '\n'};
constexpr int kDescriptorBytes = 128;

class Writer {
 public:
  template <typename T>
  void Put(T value) {
    const auto* bytes = reinterpret_cast<const std::uint8_t*>(&value);
    out_.insert(out_.end(), bytes, bytes + sizeof(T));
  }
  void PutBytes(const void* data, std::size_t size) {
    const auto* bytes = static_cast<const std::uint8_t*>(data);
    out_.insert(out_.end(), bytes, bytes + size);
  }
  void PutVector3(const Eigen::Vector3d& v) {
    for (int i = 0; i < 3; ++i) Put<double>(v[i]);
  }
  std::vector<std::uint8_t> Take() { return std::move(out_); }

 private:
  std::vector<std::uint8_t> out_;
};

// Every read checks the bytes left: a truncated or corrupt file is refused, never read past.
class Reader {
 public:
  Reader(const std::uint8_t* data, std::size_t size) : data_(data), size_(size) {}
  template <typename T>
  T Get() {
    T value;
    std::memcpy(&value, Take(sizeof(T)), sizeof(T));
    return value;
  }
  const std::uint8_t* Take(std::size_t size) {
    OMNIRIG_CHECK(size <= size_ - offset_, "the saved map is truncated at byte " << offset_);
    const std::uint8_t* at = data_ + offset_;
    offset_ += size;
    return at;
  }
  // A count of items of at least `min_item_bytes` each: no more than the bytes left can hold.
  std::uint32_t Count(std::size_t min_item_bytes, const char* what) {
    const auto n = Get<std::uint32_t>();
    OMNIRIG_CHECK(
        n <= (size_ - offset_) / min_item_bytes,
        "the saved map is truncated or corrupt: " << n << " " << what << " do not fit in its size");
    return n;
  }
  Eigen::Vector3d GetVector3() {
    Eigen::Vector3d v;
    for (int i = 0; i < 3; ++i) v[i] = Get<double>();
    return v;
  }
  bool AtEnd() const { return offset_ == size_; }

 private:
  const std::uint8_t* data_;
  std::size_t size_;
  std::size_t offset_ = 0;
};

void PutKeyframe(const SavedKeyframe& k, Writer* w) {
  w->Put<std::uint32_t>(static_cast<std::uint32_t>(k.name.size()));
  w->PutBytes(k.name.data(), k.name.size());
  const Eigen::Quaterniond q = k.rig_from_world.rotation.normalized();
  for (double v : {q.w(), q.x(), q.y(), q.z()}) w->Put<double>(v);
  w->PutVector3(k.rig_from_world.translation);
  w->Put<std::uint8_t>(k.linked ? 1 : 0);
  w->Put<double>(k.path_m);
  const int n = k.cam0.size();
  OMNIRIG_CHECK(k.cam0.descriptors.rows == n && k.cam0.descriptors.cols == kDescriptorBytes &&
                    k.cam0.descriptors.type() == CV_8U && k.cam0.descriptors.isContinuous(),
                "a saved keyframe needs one 128-byte descriptor per cam0 feature");
  w->Put<std::uint32_t>(static_cast<std::uint32_t>(n));
  for (int f = 0; f < n; ++f) {
    w->Put<double>(k.cam0.pixels[f].x());
    w->Put<double>(k.cam0.pixels[f].y());
    w->PutVector3(k.cam0.bearings[f]);
    w->PutBytes(k.cam0.rgb[f].data(), 3);
    w->PutBytes(k.cam0.descriptors.ptr(f), kDescriptorBytes);
  }
  for (int id : k.landmark_of[0]) w->Put<std::int32_t>(id);
  w->Put<std::uint32_t>(static_cast<std::uint32_t>(k.num_cam1_features));
  for (int id : k.landmark_of[1]) w->Put<std::int32_t>(id);
  w->Put<std::uint32_t>(static_cast<std::uint32_t>(k.stereo.size()));
  for (const StereoPoint& s : k.stereo) {
    w->Put<std::int32_t>(s.feature0);
    w->Put<std::int32_t>(s.feature1);
    w->PutVector3(s.point_in_cam0);
    w->Put<double>(s.range_std_m);
    w->Put<double>(s.parallax_rad);
    w->Put<double>(s.epipolar_error_rad);
  }
}

SavedKeyframe GetKeyframe(Reader* r) {
  SavedKeyframe k;
  const std::uint32_t name_size = r->Count(1, "name bytes");
  const std::uint8_t* name = r->Take(name_size);
  k.name.assign(reinterpret_cast<const char*>(name), name_size);
  double q[4];
  for (double& v : q) v = r->Get<double>();
  const Eigen::Quaterniond rotation(q[0], q[1], q[2], q[3]);
  OMNIRIG_CHECK(std::abs(rotation.norm() - 1.0) < 1e-6,
                "the saved map is corrupt: keyframe " << k.name << "'s rotation is not unit");
  k.rig_from_world = Rigid3d(rotation, r->GetVector3());
  k.linked = r->Get<std::uint8_t>() != 0;
  k.path_m = r->Get<double>();
  const std::uint32_t n = r->Count(8 * 5 + 3 + kDescriptorBytes + 4, "features");
  k.cam0.descriptors.create(static_cast<int>(n), kDescriptorBytes, CV_8U);
  for (std::uint32_t f = 0; f < n; ++f) {
    const double x = r->Get<double>();
    const double y = r->Get<double>();
    k.cam0.pixels.emplace_back(x, y);
    k.cam0.bearings.push_back(r->GetVector3());
    std::array<std::uint8_t, 3> rgb;
    std::memcpy(rgb.data(), r->Take(3), 3);
    k.cam0.rgb.push_back(rgb);
    std::memcpy(k.cam0.descriptors.ptr(static_cast<int>(f)), r->Take(kDescriptorBytes),
                kDescriptorBytes);
  }
  for (std::uint32_t f = 0; f < n; ++f) k.landmark_of[0].push_back(r->Get<std::int32_t>());
  k.num_cam1_features = static_cast<int>(r->Count(4, "cam1 features"));
  for (int f = 0; f < k.num_cam1_features; ++f) {
    k.landmark_of[1].push_back(r->Get<std::int32_t>());
  }
  const std::uint32_t num_stereo = r->Count(8 + 8 * 6, "stereo points");
  for (std::uint32_t s = 0; s < num_stereo; ++s) {
    StereoPoint& p = k.stereo.emplace_back();
    p.feature0 = r->Get<std::int32_t>();
    p.feature1 = r->Get<std::int32_t>();
    OMNIRIG_CHECK(
        p.feature0 >= 0 && p.feature0 < static_cast<int>(n) && p.feature1 >= 0 &&
            p.feature1 < k.num_cam1_features,
        "the saved map is corrupt: keyframe " << k.name << " has a stereo point out of range");
    p.point_in_cam0 = r->GetVector3();
    p.range_std_m = r->Get<double>();
    p.parallax_rad = r->Get<double>();
    p.epipolar_error_rad = r->Get<double>();
    p.pixel0 = k.cam0.pixels[p.feature0];
    p.rgb = k.cam0.rgb[p.feature0];
  }
  return k;
}

void PutLandmark(const Landmark& l, Writer* w) {
  w->PutVector3(l.point_in_world);
  w->PutBytes(l.rgb.data(), 3);
  w->Put<std::uint32_t>(static_cast<std::uint32_t>(l.observations.size()));
  for (const Observation& o : l.observations) {
    w->Put<std::int32_t>(o.frame);
    w->Put<std::uint8_t>(static_cast<std::uint8_t>(o.camera));
    w->Put<std::int32_t>(o.feature);
    w->Put<double>(o.pixel.x());
    w->Put<double>(o.pixel.y());
  }
}

Landmark GetLandmark(const std::vector<SavedKeyframe>& keyframes, Reader* r) {
  Landmark l;
  l.point_in_world = r->GetVector3();
  std::memcpy(l.rgb.data(), r->Take(3), 3);
  const std::uint32_t n = r->Count(4 + 1 + 4 + 16, "observations");
  for (std::uint32_t i = 0; i < n; ++i) {
    Observation& o = l.observations.emplace_back();
    o.frame = r->Get<std::int32_t>();
    o.camera = r->Get<std::uint8_t>();
    o.feature = r->Get<std::int32_t>();
    o.pixel.x() = r->Get<double>();
    o.pixel.y() = r->Get<double>();
    OMNIRIG_CHECK(o.frame >= 0 && o.frame < static_cast<int>(keyframes.size()) && o.camera <= 1,
                  "the saved map is corrupt: an observation of an unknown keyframe or camera");
    const SavedKeyframe& k = keyframes[o.frame];
    OMNIRIG_CHECK(o.feature >= 0 && o.feature < static_cast<int>(k.landmark_of[o.camera].size()),
                  "the saved map is corrupt: an observation of an unknown feature");
  }
  return l;
}

}  // namespace

std::vector<std::uint8_t> SerializeSavedMap(const SavedMap& map) {
  Writer w;
  w.PutBytes(kMagic, sizeof(kMagic));
  w.Put<std::uint32_t>(kSavedMapVersion);
  w.Put<std::uint32_t>(static_cast<std::uint32_t>(map.keyframes.size()));
  w.Put<std::uint32_t>(static_cast<std::uint32_t>(map.landmarks.size()));
  for (const SavedKeyframe& k : map.keyframes) PutKeyframe(k, &w);
  for (const Landmark& l : map.landmarks) PutLandmark(l, &w);
  w.PutBytes(kEnd, sizeof(kEnd));
  return w.Take();
}

SavedMap DeserializeSavedMap(const std::uint8_t* data, std::size_t size) {
  Reader r(data, size);
  OMNIRIG_CHECK(size >= sizeof(kMagic) && std::memcmp(data, kMagic, sizeof(kMagic)) == 0,
                "not an omnirig saved map (it does not start with \"OMNIRIG-MAP\")");
  r.Take(sizeof(kMagic));
  const auto version = r.Get<std::uint32_t>();
  OMNIRIG_CHECK(version == kSavedMapVersion, "saved map format version "
                                                 << version << " is not one this omnirig reads (it "
                                                 << "reads version " << kSavedMapVersion << ")");
  SavedMap map;
  const std::uint32_t num_keyframes = r.Count(64, "keyframes");
  const std::uint32_t num_landmarks = r.Count(31, "landmarks");
  for (std::uint32_t k = 0; k < num_keyframes; ++k) map.keyframes.push_back(GetKeyframe(&r));
  for (std::uint32_t l = 0; l < num_landmarks; ++l) {
    map.landmarks.push_back(GetLandmark(map.keyframes, &r));
  }
  for (const SavedKeyframe& k : map.keyframes) {
    for (const std::vector<int>& of : k.landmark_of) {
      for (int id : of) {
        OMNIRIG_CHECK(
            id >= -1 && id < static_cast<int>(num_landmarks),
            "the saved map is corrupt: keyframe " << k.name << " sees an unknown landmark");
      }
    }
  }
  OMNIRIG_CHECK(std::memcmp(r.Take(sizeof(kEnd)), kEnd, sizeof(kEnd)) == 0 && r.AtEnd(),
                "the saved map is corrupt: it does not end where its contents do");
  return map;
}

void WriteSavedMap(const std::filesystem::path& path, const SavedMap& map) {
  const std::vector<std::uint8_t> bytes = SerializeSavedMap(map);
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) throw std::runtime_error("cannot write " + path.string());
  out.write(reinterpret_cast<const char*>(bytes.data()),
            static_cast<std::streamsize>(bytes.size()));
  if (!out) throw std::runtime_error("failed writing " + path.string());
}

SavedMap ReadSavedMap(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  OMNIRIG_CHECK(in, "cannot open the saved map " << path.filename().string());
  const std::vector<std::uint8_t> bytes((std::istreambuf_iterator<char>(in)),
                                        std::istreambuf_iterator<char>());
  try {
    return DeserializeSavedMap(bytes.data(), bytes.size());
  } catch (const InvalidArgument& e) {
    throw InvalidArgument(path.filename().string() + ": " + e.what());
  }
}

}  // namespace omnirig::slam
