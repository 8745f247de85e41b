"""The ground app's web interface: server-rendered pages (Jinja2) for survey engineers, signed in with a user
token into a cookie session; every form carries a CSRF token. Mounted by `ground.api.app.create_app`."""
