from django.urls import path

from archives import views

app_name = "archives"
urlpatterns = [
    path("models/import/", views.model_import, name="model-import"),
    path("models/import/cancel/", views.model_import_cancel, name="model-import-cancel"),
    path("models/import/bucket/", views.model_import_bucket, name="model-import-bucket"),
    path("models/<int:pk>/download/logs/", views.model_logs, name="model-logs"),
    *(
        path(
            f"models/<int:pk>/download/{kind}/",
            views.model_export,
            {"kind": kind},
            name=f"model-export-{kind}",
        )
        for kind in ("physical", "onnx", "virtual")
    ),
]
