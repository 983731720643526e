"""The core every component shares, pure: the error tree's base, the frame record, the mask bit
layout, the image codec, reading a user's JSON file, text metrics, where shipped files live."""
