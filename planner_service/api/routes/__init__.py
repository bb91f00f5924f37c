"""The API's routes, one module per resource; :func:`..app.create_app` includes them."""
