// Links the OpenImageIO back-end as this executable's (see image.h).
#include "image/image.h"

namespace hemirad::image {
const Backend& backend() { return oiio_backend(); }
}  // namespace hemirad::image
