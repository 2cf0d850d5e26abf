"""The site's date formats (settings.FORMAT_MODULE_PATH): one way to write a moment on every
page, whichever filter or tag writes it."""
