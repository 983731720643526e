"""The live session page: server-rendered HTML at ``/``, a little JavaScript, no build step.

The HTML shells (``/``, ``/sessions/{id}``) hold nothing secret and need no key; everything
about sessions comes from key-protected routes the page's script calls with the key in the
``X-API-Key`` header (the key is typed into the login form or given in the URL fragment, which
browsers never send, so it never reaches a query string or a log).
"""

from .routes import mount_ui

__all__ = ["mount_ui"]
