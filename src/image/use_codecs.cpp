// Links the codecs back-end as this executable's (see image.h).
#include "image/image.h"

namespace hemirad::image {
const Backend& backend() { return codecs_backend(); }
}  // namespace hemirad::image
